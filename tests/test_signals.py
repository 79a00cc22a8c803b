"""Signals held back over checkpoint writes (plls_bench/core/signals.py): a scheduler's signal that lands
inside torch.save runs its handler after the write, and the checkpoint is whole."""
from __future__ import annotations

import io
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from plls_bench.core.signals import signals_deferred
from plls_bench.rundirs.run_dir import Run
from plls_bench.train import loop
from plls_bench.train.loop import Progress
from tests.conftest import compose_preset
from tests.test_loop import Toy


@pytest.fixture
def requeue_handler() -> Iterator[list[int]]:
    """SIGUSR2 ends the process as submitit's requeue handler does (``sys.exit`` from the handler);
    the signals it received, in order; the previous handler is back afterwards."""
    received: list[int] = []

    def handler(signum: int, frame: object) -> None:
        received.append(signum)
        raise SystemExit(-1)

    previous = signal.signal(signal.SIGUSR2, handler)
    yield received
    signal.signal(signal.SIGUSR2, previous)


class SignalsAtWrite(io.BytesIO):
    """A file that signals its own process at its ``nth`` write, as a scheduler's signal would
    arrive in the middle of torch.save. Unheld, the handler's exit there surfaces as torch's
    ``RuntimeError: ... unexpected pos`` (the CI failure this guards against) or a truncated file."""

    def __init__(self, signum: int, nth: int) -> None:
        super().__init__()
        self.signum, self.nth, self.writes = signum, nth, 0

    def write(self, data: bytes) -> int:  # type: ignore[override]
        self.writes += 1
        if self.writes == self.nth:
            os.kill(os.getpid(), self.signum)
        return super().write(data)


@pytest.mark.parametrize("nth", [1, 3])
def test_a_signal_inside_torch_save_waits_for_the_write(requeue_handler: list[int], nth: int) -> None:
    weights = {"w": torch.arange(4096, dtype=torch.float32)}
    target = SignalsAtWrite(signal.SIGUSR2, nth)
    with pytest.raises(SystemExit):
        with signals_deferred():
            torch.save(weights, target)
            assert requeue_handler == [], "the handler ran inside the block"
    assert target.writes > nth and requeue_handler == [signal.SIGUSR2]
    loaded = torch.load(io.BytesIO(target.getvalue()), weights_only=True)
    assert torch.equal(loaded["w"], weights["w"])


def test_handlers_are_back_after_a_quiet_block(requeue_handler: list[int]) -> None:
    before = {number: signal.getsignal(number) for number in (signal.SIGUSR2, signal.SIGTERM, signal.SIGINT)}
    with signals_deferred():
        with signals_deferred():  # nested: the inner block hands what arrives to the outer
            pass
    assert {number: signal.getsignal(number) for number in before} == before
    assert requeue_handler == []


def test_nested_blocks_deliver_once_after_the_outer(requeue_handler: list[int]) -> None:
    with pytest.raises(SystemExit):
        with signals_deferred():
            with signals_deferred():
                os.kill(os.getpid(), signal.SIGUSR2)
            assert requeue_handler == [], "the inner block's end delivered it inside the outer"
    assert requeue_handler == [signal.SIGUSR2]


class SignalledMidCheckpoint(Toy):
    """A requeue signal arrives while the trainer writes its checkpoint."""

    def checkpoint(self, at: Progress) -> None:
        os.kill(os.getpid(), signal.SIGUSR2)
        super().checkpoint(at)


def test_the_training_loop_finishes_a_checkpoint_before_a_signal_ends_it(runs_dir: Path,
                                                                        requeue_handler: list[int]) -> None:
    run = Run(runs_dir / "toy")
    toy = SignalledMidCheckpoint(run)
    with pytest.raises(SystemExit):
        loop.train(toy, run, compose_preset("mountaincar_ppo", runs_dir))
    assert requeue_handler == [signal.SIGUSR2]
    assert toy.calls[-2:] == ["checkpoint 0", "close"]
    assert (run.path / "toy.txt").read_text().split() == ["0", "0", "0", "1"], "the checkpoint was written whole"


def test_a_repeated_signal_runs_its_handler_once() -> None:
    received: list[int] = []
    previous = signal.signal(signal.SIGUSR1, lambda signum, frame: received.append(signum))
    try:
        with signals_deferred():
            os.kill(os.getpid(), signal.SIGUSR1)
            os.kill(os.getpid(), signal.SIGUSR1)
        assert received == [signal.SIGUSR1]
    finally:
        signal.signal(signal.SIGUSR1, previous)
