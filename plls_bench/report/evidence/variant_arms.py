"""Every variant of a preset the runs or the records hold, beside the preset's default runs.

A variant is a run dir ``<preset>/<variant>`` other than the default's (``default``, or the backend
tag a profile's default runs carry): an ablation override (``reproduce --override``,
``python -m plls_bench ... KEY=VALUE``) or a declared sweep's value alike. Each is compared with the
preset's default where both were measured (:func:`plls_bench.report.evidence.matched.matched`): final return
and mean return over the curve per trial, and the final return tested under the declared protocol
(:func:`plls_bench.report.evidence.protocol.compare_arms`, its p two-sided), only at one budget; a variant that
cannot be tested says what it lacks.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from plls_bench.config.tasks import ENV_BACKENDS
from plls_bench.pipeline.runner_registry import RUNNERS
from plls_bench.report.evidence.load import DEFAULT_VARIANT, DEFAULT_VARIANTS, Runs
from plls_bench.report.evidence.matched import Matched, NotJudged, matched
from plls_bench.report.evidence.protocol import compare_arms
from plls_bench.report.evidence.returns import Curves, load_curves
from plls_bench.report.evidence.trials import Experiment
from plls_bench.rundirs.run_dir import backend_tag, iter_run_dirs

# Variants are compared in env steps, the unit budgets are stated in, whatever the collector's --x-axis:
# an override may change the env steps of an iteration (env.action_repeat, algo.ppo.n_envs), and the same
# iteration of two such arms is not the same budget.
X_AXIS = "env_steps"
# How the protocol's outcomes read for a variant (arm a) against its default (arm b).
OUTCOMES = {"a better": "variant higher", "b better": "default higher", "equivalent": "equivalent",
            "undecided": "no difference found", "too few trials": "not tested"}


@dataclass
class Judged:
    """A variant beside its default: per-trial ``final`` and ``curve`` scores ``(n,)`` of each arm
    (variant first; empty where there are none), where they were read (``at``) and the verdict."""

    final: list[np.ndarray]
    curve: list[np.ndarray]
    at: str
    verdict: str
    outcome: str
    test: dict[str, float | int | str | None]


@dataclass
class Variant:
    """One ``<preset>/<variant>`` and the preset's default runs it is compared with; curves are
    None for a runner that logs no evaluation returns."""

    preset: str
    exp: Experiment
    default: Experiment
    curves: Curves | None
    default_curves: Curves | None

    @property
    def name(self) -> str:
        return self.exp.variant


def variant_of(dirname: str) -> str:
    """The collector's variant of a run-dir variant: the backend tag a profile adds left off
    (``repr.action.latent_dim=8,env.backend=envpool`` -> ``repr.action.latent_dim=8``)."""
    if dirname in DEFAULT_VARIANTS:
        return DEFAULT_VARIANT
    tags = {backend_tag(backend) for backend in ENV_BACKENDS} - {""}
    return ",".join(part for part in dirname.split(",") if part not in tags) or DEFAULT_VARIANT


def _natural(text: str) -> list[str | int]:
    """Sort key putting ``latent_dim=8`` before ``latent_dim=16``."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]


def found_variants(runs: Runs) -> dict[str, list[str]]:
    """Preset -> its variants (not the default) with a ``seed=<k>`` dir under the runs dir or the
    records, presets and variants in natural order."""
    found: dict[str, set[str]] = {}
    for root in (r for r in (runs.root, runs.records_root) if r is not None):
        for path in iter_run_dirs(root):
            preset, variant = path.parts[-3], variant_of(path.parts[-2])
            if variant != DEFAULT_VARIANT:
                found.setdefault(preset, set()).add(variant)
    return {preset: sorted(found[preset], key=_natural) for preset in sorted(found)}


def load_variant(runs: Runs, preset: str, variant: str, x_axis: str = X_AXIS) -> Variant:
    """``preset/variant`` and the preset's default, with their return curves where the runner logs any."""
    exp, default = runs.experiment(preset, variant), runs.experiment(preset)
    runner = exp.cfg("runner")
    if runner not in RUNNERS or not RUNNERS[runner].trains_policy:
        return Variant(preset, exp, default, None, None)
    return Variant(preset, exp, default, load_curves(runs, exp, variant, x_axis),
                   load_curves(runs, default, DEFAULT_VARIANT, x_axis) if default.trials else None)


def judge(runs: Runs, variant: Variant) -> Judged:
    """The variant's scores beside the default's, and the test of their final returns where one budget
    and finished trials of both allow it; otherwise each arm's own scores and what is missing."""
    own = [c for c in (variant.curves, variant.default_curves) if c is not None]
    missing = _missing(variant)
    if missing is None:
        try:
            pair = matched(*own, runs=runs)
        except NotJudged as err:
            missing = str(err)
        else:
            return _tested(pair)
    scores = [_own_scores(c) for c in own]
    finals = [s[0] for s in scores] + [np.zeros(0)] * (2 - len(scores))
    curves = [s[1] for s in scores] + [np.zeros(0)] * (2 - len(scores))
    return Judged(finals, curves, "each arm at its own last evaluation", f"not judged: {missing}", "not judged", {})


def _missing(variant: Variant) -> str | None:
    """What keeps the variant from a test against its default (None: nothing, so far)."""
    if variant.curves is None:
        return f"the {variant.exp.cfg('runner') or 'unknown'} runner logs no evaluation returns"
    if not variant.curves.n:
        return "no evaluation returns of the variant"
    if not variant.default.trials or variant.default_curves is None or not variant.default_curves.n:
        return f"no runs of the default ({variant.preset}/{DEFAULT_VARIANT})"
    if variant.exp.budget != variant.default.budget:
        return (f"the variant ran at budget {variant.exp.budget}, the default at {variant.default.budget}: "
                f"run both at one budget")
    return None


def _own_scores(curves: Curves) -> tuple[np.ndarray, np.ndarray]:
    """One arm's final and mean-over-the-curve returns ``(n,)`` on the evaluations all its finished trials reach."""
    try:
        values = matched(curves).values[0]
    except NotJudged:
        return np.zeros(0), np.zeros(0)
    return values[:, -1], values.mean(axis=1)


def _tested(pair: Matched) -> Judged:
    """Both arms on their common evaluations, the final returns tested (variant = arm a). The protocol's
    p is two-sided whatever its ``direction``, which only names the arm found higher: "greater" reads a
    significant difference as "a better" when the variant's mean is the higher, "b better" otherwise."""
    finals = [v[:, -1] for v in pair.values]
    comparison = compare_arms(finals[0], finals[1], direction="greater")
    outcome = OUTCOMES.get(comparison.outcome, comparison.outcome)
    extra = "" if comparison.n_for_power is None or comparison.outcome != "undecided" else (
        f"; {comparison.n_for_power} trials per arm for 80% power at this effect")
    verdict = f"{outcome}: {comparison.text}{extra}" if comparison.outcome != "too few trials" else comparison.text
    test = {"test": comparison.test, "statistic": comparison.statistic, "p": comparison.p,
            "n_for_power": comparison.n_for_power, "protocol_outcome": comparison.outcome}
    return Judged(finals, [v.mean(axis=1) for v in pair.values], pair.at, verdict, outcome, test)
