"""A learner stopped as Ctrl-C would stop it, and its metric rows for comparing resumed runs."""
from __future__ import annotations

from pathlib import Path

import pytest

from plls_bench.pipeline.execute import execute
from plls_bench.rundirs.run_dir import Run

VOLATILE = ("wall_s", "perf/")  # timing fields differ between any two runs


def interrupted(cfg, run_dir: Path, trainer: type, after: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Run ``cfg`` and raise KeyboardInterrupt in ``trainer.train_iteration`` once ``after``
    iterations are done (a checkpoint at ``after`` is written first)."""
    real = trainer.train_iteration

    def stop(self, at):
        if at.iteration == after:
            raise KeyboardInterrupt
        return real(self, at)

    with monkeypatch.context() as patch:
        patch.setattr(trainer, "train_iteration", stop)
        with pytest.raises(KeyboardInterrupt):
            execute(cfg, run_dir)


def rows(run_dir: Path, stream: str) -> list[dict]:
    """The run's ``stream`` rows without their timing fields."""
    return [{k: v for k, v in row.items() if not k.startswith(VOLATILE)}
            for row in Run(run_dir).read_metrics(stream)]
