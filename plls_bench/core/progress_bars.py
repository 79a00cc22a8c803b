"""Progress bars fit for a terminal and for log files.

On a terminal, :func:`progress_bar` is a plain tqdm bar. When stderr is not a terminal (a SLURM
log, ``2> file``, a joblib worker) tqdm's carriage-return redraws pile up into megabytes of one
"line"; there the same bar logs one plain line through :mod:`logging` when it starts, at most
every :data:`LOG_INTERVAL_S` seconds, and when it ends.
"""
from __future__ import annotations

import logging
import math
import sys
import time
from typing import Any

from tqdm.auto import tqdm

LOG_INTERVAL_S = 10.0  # seconds between two progress lines in a log file
_LOG_FORMAT = "{desc}: {n_fmt}/{total_fmt} [{elapsed}<{remaining}, {rate_fmt}{postfix}]"
log = logging.getLogger(__name__)


class _Discard:
    """Where tqdm's own terminal output goes when the bar logs instead."""

    def write(self, text: str) -> None:
        pass

    def flush(self) -> None:
        pass


class _LogBar(tqdm):
    """tqdm whose redraws become log records: the first, the last, and at most one every
    :data:`LOG_INTERVAL_S` between them (``set_postfix`` redraws too, past ``mininterval``)."""

    _logged_at = -math.inf
    _closing = False

    def display(self, msg: str | None = None, pos: int | None = None) -> bool:
        now = time.monotonic()
        if self._closing or now - self._logged_at >= LOG_INTERVAL_S:
            self._logged_at = now
            log.info(msg if msg is not None else str(self))
        return True

    def close(self) -> None:
        self._closing = True
        super().close()


def progress_bar(iterable: Any = None, **kwargs: Any) -> tqdm:
    """A tqdm bar (same arguments) on a terminal, a :class:`_LogBar` otherwise."""
    if sys.stderr.isatty():
        return tqdm(iterable, **kwargs)
    return _LogBar(iterable, file=_Discard(), mininterval=LOG_INTERVAL_S, bar_format=_LOG_FORMAT, **kwargs)
