"""The collector's view of one trial, one ``<experiment>/<variant>`` and one thing it could not read.

:class:`plls_bench.report.evidence.load.Runs` builds them; figures and claims read them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Gap:
    """Something the collector expected and could not use; ``seed`` is None for a whole run."""

    experiment: str
    variant: str
    seed: int | None
    problem: str

    def __str__(self) -> str:
        where = f"{self.experiment}/{self.variant}" + ("" if self.seed is None else f" seed={self.seed}")
        return f"{where}: {self.problem}"


@dataclass
class Trial:
    """One usable run directory (it has a readable config.json)."""

    seed: int
    path: Path
    state: str  # done | running | failed | unknown (no readable status.json)
    config: dict[str, Any]
    source: str = "run"  # run (under the runs dir) | record (committed, under the records dir) | partial

    def cfg(self, dotted: str, default: Any = None) -> Any:
        """A value of the run's resolved config by dotted key, e.g. ``algo.ppo.n_envs``."""
        node: Any = self.config
        for part in dotted.split("."):
            if not isinstance(node, dict) or part not in node:
                return default
            node = node[part]
        return node


@dataclass
class Experiment:
    """The trials of one ``<experiment>/<variant>`` that share one config (seed aside)."""

    name: str
    variant: str
    trials: list[Trial] = field(default_factory=list)

    @property
    def budget(self) -> str | None:
        return self.trials[0].cfg("budget.name") if self.trials else None

    @property
    def budget_text(self) -> str:
        return f"budget {self.budget}" if self.budget else "no runs"

    def cfg(self, dotted: str, default: Any = None) -> Any:
        return self.trials[0].cfg(dotted, default) if self.trials else default
