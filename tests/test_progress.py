"""Progress bars in log files: plain lines, the first, the last and at most one per interval."""
from __future__ import annotations

import logging

import pytest

from plls_bench.core.progress_bars import progress_bar


def test_a_bar_off_a_terminal_logs_plain_lines_not_redraws(caplog: pytest.LogCaptureFixture) -> None:
    # pytest captures stderr, so it is not a terminal here
    with caplog.at_level(logging.INFO, logger="plls_bench.core.progress_bars"):
        with progress_bar(total=1000, desc="demo", unit="step") as bar:
            for _ in range(1000):
                bar.update(1)
                bar.set_postfix(loss=0.5)  # redraws on every call on a terminal
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and lines[0].startswith("demo: 0/1000") and lines[1].startswith("demo: 1000/1000")
    assert not any("\r" in line for line in lines)


def test_a_disabled_bar_logs_nothing(caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="plls_bench.core.progress_bars"):
        for _ in progress_bar(range(10), desc="off", disable=True):
            pass
    assert not caplog.records
