"""SIGTERM as an exception, for the two processes that must act on it before they end: a trial
(its status says ``stopped``, :mod:`plls_bench.pipeline.execute`) and ``reproduce``'s queue (it passes the
signal on to the trials it started, :mod:`plls_bench.pipeline.launch`)."""
from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

TERMINATED_EXIT_CODE = 128 + signal.SIGTERM  # what a shell reports for a process SIGTERM ended


class Terminated(BaseException):
    """SIGTERM arrived (``kill``, SLURM's preemption, a session's end)."""


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """Turn SIGTERM into :class:`Terminated` inside the block (the default action ends the process
    before it can act); once it has fired, later SIGTERMs are ignored, also after the block, since
    the process is on its way out. Only the main thread can install handlers: elsewhere SIGTERM
    keeps its default action."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    fired = False

    def handler(signum: int, frame: object) -> None:
        nonlocal fired
        fired = True
        # one is enough: a second (a process group's kill, then reproduce passing it on) must not
        # end the process by the default action while it writes that it stopped
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise Terminated(f"terminated by signal {signal.Signals(signum).name}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        if not fired:
            signal.signal(signal.SIGTERM, previous)


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold back every signal with a Python handler (SIGTERM as :class:`Terminated`, submitit's
    requeue signal, Ctrl-C) until the block ends, then run the handler of each signal that arrived,
    once, in order of arrival (the first that raises ends it: a repeat adds nothing).
    For checkpoint writes: a handler's exception raised inside ``torch.save``'s zip writer is
    replaced by torch's own ``RuntimeError: ... unexpected pos``, so a job signalled mid-write
    failed instead of requeueing or stopping. The handlers are swapped, not the signal mask
    blocked: a process-wide signal can land on any thread that leaves it unblocked."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handlers = {number: handler for number in signal.valid_signals()
                if callable(handler := signal.getsignal(number))}
    arrived: list[int] = []

    def record(signum: int, frame: object) -> None:
        arrived.append(signum)

    for number in handlers:
        signal.signal(number, record)
    try:
        yield
    finally:
        for number, handler in handlers.items():
            signal.signal(number, handler)
        for signum in dict.fromkeys(arrived):
            handlers[signum](signum, None)
