"""Read run directories for the collector, tolerant of every gap, and never write to them.

Each registry id gets a fresh :class:`Runs` view; everything it could not read (a missing run or
seed, a torn jsonl line, a failed or unfinished run, a corrupt file) is recorded as a :class:`Gap`
in that view, so the id reports exactly the gaps that touch it. Only the files listed in the
docs/architecture.md's "What each runner writes" table are read.

Trials come from the runs dir and from the committed records (``plls_bench/records.py``; partial
records, under ``records/partial/``, are not trials: only ``<records>/<experiment>/<variant>``; see
:meth:`Runs.partial_trials` for the one thing read from them). A local
run replaces the record of the same seed when their configs agree; otherwise both compete as
groups of one config. A group that can be judged (:data:`MIN_TRIALS` finished trials at a budget
records keep) wins over one that cannot, then the highest budget, then the largest, then the local
one: a smoke run on a fresh clone never hides real-budget records, and the first two finished trials
of a longer budget do not hide three finished ones of a shorter budget until they can be judged.
"""
from __future__ import annotations

import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from plls_bench.config.learning import BUDGET_NAMES
from plls_bench.config.tasks import ENV_BACKENDS
from plls_bench.core.atomic_files import read_json, scan_jsonl
from plls_bench.report.evidence.identity import config_diff, pooling_identity
from plls_bench.report.evidence.trials import Experiment, Gap, Trial
from plls_bench.rundirs.record_layout import EXCLUDED_BUDGETS, PARTIAL_DIR
from plls_bench.rundirs.run_dir import STATUS_DONE, variant_name

# The fewest finished trials per arm from which a claim about a stochastic quantity (a return, a
# convergence point, a trained model's MSE) is judged. A 95% bootstrap CI over one trial does not
# exist, and over two it is just their range (each resample is a, b or their mean): it says nothing
# about the spread of a third. Three is the fewest that give an interval worth reading; fewer is
# "not run at this budget". Deterministic quantities (parameter counts) need one.
MIN_TRIALS = 3

DEFAULT_VARIANT = "default"
# A profile's own runs of a preset live in ``default``, or in ``env.backend=<b>`` when the profile
# runs the task on another simulator engine (runs.variant_name): both are the preset's default runs.
DEFAULT_VARIANTS = tuple(variant_name("auto", "", backend) for backend in ENV_BACKENDS)


def variant_dirs(variant: str) -> tuple[str, ...]:
    """The run-dir variants that hold ``name/variant``'s runs: for ``default``, every profile's
    default runs; for an override (``repr.action.latent_dim=8``, a sweep value), that override as
    each backend names it (``repr.action.latent_dim=8,env.backend=envpool`` where a profile runs
    the task on envpool)."""
    if variant == DEFAULT_VARIANT:
        return DEFAULT_VARIANTS
    return tuple(dict.fromkeys(variant_name("auto", variant, backend) for backend in ENV_BACKENDS))


_SEED_DIR = re.compile(r"^seed=(\d+)$")


class Runs:
    """A read-only view of a runs dir that records every gap it meets."""

    def __init__(self, runs_dir: str | Path | None, records_dir: str | Path | None = None) -> None:
        self.root = None if runs_dir is None else Path(runs_dir)  # None: the records alone
        self.records_root = None if records_dir is None else Path(records_dir)
        self.gaps: list[Gap] = []
        self._experiments: dict[tuple[str, str], Experiment] = {}

    # gaps -------------------------------------------------------------------
    def gap(self, exp: Experiment, trial: Trial | None, problem: str) -> None:
        item = Gap(exp.name, exp.variant, None if trial is None else trial.seed, problem)
        if item not in self.gaps:
            self.gaps.append(item)

    # experiments --------------------------------------------------------------
    def experiment(self, name: str, variant: str = DEFAULT_VARIANT) -> Experiment:
        """The consistent trials of ``name/variant`` (:func:`variant_dirs`); gaps for missing,
        empty or odd run dirs."""
        key = (name, variant)
        if key not in self._experiments:
            self._experiments[key] = self._scan(name, variant)
        return self._experiments[key]

    def _scan(self, name: str, variant: str) -> Experiment:
        exp = Experiment(name, variant)
        variants = variant_dirs(variant)
        sources = [(base, kind) for base, kind in ((self.root, "run"), (self.records_root, "record"))
                   if base is not None]
        roots = [(base / name / v, kind) for base, kind in sources for v in variants]
        if not any(root.is_dir() for root, _ in roots):
            expected = " or ".join(str(base / name / variants[0]) for base, _ in sources)
            self.gap(exp, None, f"no runs (expected {expected})")
            return exp
        candidates, seen = [], set()
        for root, source in roots:
            for path in sorted(root.iterdir(), key=_seed_order) if root.is_dir() else []:
                match = _SEED_DIR.match(path.name)
                if not path.is_dir() or not match:
                    self.gap(exp, None, f"{path.name}: not a seed=<k> run dir, ignored")
                    continue
                seen.add(int(match.group(1)))
                trial = self._trial(exp, int(match.group(1)), path, source)
                if trial is not None and not _replaced(trial, candidates):
                    candidates.append(trial)
        exp.trials = self._consistent(exp, candidates)
        self._missing_seeds(exp, {t.seed for t in exp.trials} if self.records_root is not None else seen)
        return exp

    def _trial(self, exp: Experiment, seed: int, path: Path, source: str = "run") -> Trial | None:
        probe = Trial(seed, path, "unknown", {}, source)
        if not any(path.iterdir()):
            self.gap(exp, probe, "empty run dir")
            return None
        config = read_json(path / "config.json")
        if not isinstance(config, dict) or not isinstance(config.get("config"), dict):
            self.gap(exp, probe, "config.json missing or unreadable: run excluded")
            return None
        status = read_json(path / "status.json")
        trial = Trial(seed, path, _state(status), config["config"], source)
        if status is None:
            self.gap(exp, trial, "status.json missing or unreadable: state unknown, data used as is")
        elif trial.state != STATUS_DONE:
            error = f" ({status.get('error')})" if status.get("error") else ""
            self.gap(exp, trial, f"status {trial.state}{error}: data used as far as they go")
        return trial

    def _consistent(self, exp: Experiment, trials: list[Trial]) -> list[Trial]:
        """Keep one group of trials whose configs agree apart from the seed: one that can be judged
        (:func:`_judgeable`), then the highest budget, then the most trials, then local runs over records."""
        groups: dict[str, list[Trial]] = {}
        for trial in trials:
            groups.setdefault(pooling_identity(trial.config), []).append(trial)
        if len(groups) <= 1:
            return sorted(trials, key=lambda t: t.seed)
        keep = max(groups.values(),
                   key=lambda g: (_judgeable(g), _budget_rank(g[0]), len(g), g[0].source == "run", -g[0].seed))
        for group in groups.values():
            if group is not keep:
                for trial in group:
                    diff = ", ".join(config_diff(keep[0].config, trial.config)[:3])
                    self.gap(exp, trial, f"config differs from seed={keep[0].seed}'s ({diff}): excluded")
        return sorted(keep, key=lambda t: t.seed)

    def _missing_seeds(self, exp: Experiment, seen: set[int]) -> None:
        expected = exp.cfg("budget.trials")
        if isinstance(expected, int):
            missing = [k for k in range(expected) if k not in seen]
            if missing:
                self.gap(exp, None, f"seed(s) {', '.join(map(str, missing))} missing "
                                    f"(budget.trials={expected})")

    def partial_trials(self, name: str, variant: str = DEFAULT_VARIANT) -> list[Trial]:
        """Unfinished trials carried as partial records (``<records>/partial/<name>/<variant>``),
        lowest seed first, whatever their budget. They are never among :meth:`experiment`'s trials
        (a curve that stops mid-way is no evidence); they serve what a started run knows in full:
        the parameter counts its architecture fixes."""
        roots = [] if self.records_root is None else [self.records_root / PARTIAL_DIR / name / v
                                                      for v in variant_dirs(variant)]
        found = []
        for root in (r for r in roots if r.is_dir()):
            for path in sorted(root.iterdir(), key=_seed_order):
                match, config = _SEED_DIR.match(path.name), read_json(path / "config.json")
                if match and path.is_dir() and isinstance(config, dict) and isinstance(config.get("config"), dict):
                    state = _state(read_json(path / "status.json"))
                    found.append(Trial(int(match.group(1)), path, state, config["config"], "partial"))
        return sorted(found, key=lambda t: t.seed)

    # files --------------------------------------------------------------------
    def records(self, exp: Experiment, trial: Trial, stream: str) -> list[dict[str, Any]]:
        """The complete records of ``metrics/<stream>.jsonl``; torn or corrupt lines are gaps."""
        scan = scan_jsonl(trial.path / "metrics" / f"{stream}.jsonl")
        if scan is None:
            self.gap(exp, trial, f"metrics/{stream}.jsonl missing")
            return []
        records = [r for r in scan.records if isinstance(r, dict)]
        bad = len(scan.corrupt_lines) + len(scan.records) - len(records)
        if bad:
            self.gap(exp, trial, f"metrics/{stream}.jsonl: {bad} corrupt line(s) skipped")
        if scan.torn_tail:
            self.gap(exp, trial, f"metrics/{stream}.jsonl: truncated last line skipped")
        return records

    def json(self, exp: Experiment, trial: Trial, relpath: str) -> dict[str, Any] | None:
        obj = read_json(trial.path / relpath)
        if not isinstance(obj, dict):
            self.gap(exp, trial, f"{relpath} missing or unreadable")
            return None
        return obj

    def arrays(self, exp: Experiment, trial: Trial, relpath: str,
               shapes: dict[str, tuple[int | None, ...]]) -> dict[str, np.ndarray] | None:
        """The arrays ``shapes`` names from an npz, checked against the shapes (None = any size);
        None (and a gap) when the file is missing, corrupt or not as the contract says."""
        try:
            with np.load(trial.path / relpath, allow_pickle=False) as npz:
                data = {key: npz[key] for key in shapes if key in npz.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
            self.gap(exp, trial, f"{relpath} missing or unreadable ({type(err).__name__})")
            return None
        problems = [f"{key} missing" for key in shapes if key not in data]
        problems += [f"{key} has shape {data[key].shape}, expected {_shape_text(want)}"
                     for key, want in shapes.items() if key in data and not _fits(data[key].shape, want)]
        if problems:
            self.gap(exp, trial, f"{relpath}: {'; '.join(problems)}")
            return None
        return data

    def first_with(self, exp: Experiment, relpath: str) -> Trial | None:
        """The lowest-seed trial holding ``relpath`` (single-run figures: filmstrips, studies)."""
        for trial in exp.trials:
            if (trial.path / relpath).is_file():
                return trial
        if exp.trials:
            self.gap(exp, None, f"no trial has {relpath}")
        return None


def _replaced(trial: Trial, candidates: list[Trial]) -> bool:
    """True when a local run of the same seed and config is already among ``candidates`` (local
    runs are scanned first and win over their records)."""
    ident = pooling_identity(trial.config)
    return any(c.seed == trial.seed and pooling_identity(c.config) == ident for c in candidates)


def _judgeable(group: list[Trial]) -> bool:
    """Whether a stochastic claim can be judged from ``group``: MIN_TRIALS finished trials at a
    budget that records keep (never smoke, whatever its trial count)."""
    finished = sum(trial.state == STATUS_DONE for trial in group)
    return finished >= MIN_TRIALS and group[0].cfg("budget.name") not in EXCLUDED_BUDGETS


def _budget_rank(trial: Trial) -> int:
    budget = trial.cfg("budget.name")
    return BUDGET_NAMES.index(budget) if budget in BUDGET_NAMES else -1


def _state(status: Any) -> str:
    """A status.json's state; ``unknown`` when it is missing or unreadable."""
    return status.get("state", "unknown") if isinstance(status, dict) else "unknown"


def _seed_order(path: Path) -> tuple[int, str]:
    """seed=2 before seed=10; odd names last."""
    match = _SEED_DIR.match(path.name)
    return (int(match.group(1)), "") if match else (1 << 62, path.name)


def _fits(shape: tuple[int, ...], want: tuple[int | None, ...]) -> bool:
    return len(shape) == len(want) and all(w is None or w == s for s, w in zip(shape, want))


def _shape_text(want: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("k" if w is None else str(w) for w in want) + ")"
