"""Every variant of a preset the runs or the records hold, beside the run it overrides (its base).

A variant is a run dir ``<preset>/<variant>`` other than the default's (``default``, or the backend
tag a profile's default runs carry): an ablation override (``reproduce --override``,
``python -m plls_bench ... KEY=VALUE``) or a declared sweep's value alike.

Its base is the run it overrides: the run dir whose variant parts are the variant's parts less every
part whose key is not a context key (:data:`CONTEXT_KEYS`: the precision; the env backend tag is
dropped before, by :func:`variant_of`). ``reproduce --precision bf16 --override X`` runs
``precision=bf16`` and ``precision=bf16,X``: X is judged against ``precision=bf16``, never against
the fp32 default. A variant of context parts alone (``precision=bf16``), or of none, has the
preset's default as its base.

Each variant is compared with its base where both were measured
(:func:`plls_bench.report.evidence.matched.matched`) under the declared protocol and its settings
(``results/paper/claims.yaml``), as the claims rows are: per trial the final return (the mean over
the last ``final_tail`` evaluations, :func:`~plls_bench.report.evidence.protocol.tail_mean`) and the
mean over the curve; the final returns tested (:func:`~plls_bench.report.evidence.protocol.compare_arms`
at the settings' alpha and min_n, its p two-sided), only at one budget; the variants of one preset
are one Holm family (:func:`~plls_bench.report.evidence.protocol.holm`), each decided at its
adjusted p; the single last evaluation is a sensitivity reading, decided on its own p. A variant
that cannot be tested says what it lacks.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from plls_bench.config.tasks import ENV_BACKENDS
from plls_bench.pipeline.runner_registry import RUNNERS
from plls_bench.report.evidence.claim_settings import ClaimSettings
from plls_bench.report.evidence.load import DEFAULT_VARIANT, DEFAULT_VARIANTS, Runs
from plls_bench.report.evidence.matched import Matched, NotJudged, matched
from plls_bench.report.evidence.protocol import TOO_FEW, Comparison, adjust, compare_arms, holm, tail_mean
from plls_bench.report.evidence.returns import Curves, load_curves
from plls_bench.report.evidence.table_formats import fmt
from plls_bench.report.evidence.trials import Experiment
from plls_bench.rundirs.run_dir import backend_tag, iter_run_dirs

# Variants are compared in env steps, the unit budgets are stated in, whatever the collector's --x-axis:
# an override may change the env steps of an iteration (env.action_repeat, algo.ppo.n_envs), and the same
# iteration of two such arms is not the same budget.
X_AXIS = "env_steps"
# Keys that set the context a run is made in, not what it ablates: a variant keeps them in its base.
# reproduce adds precision=<p> to every run of a launch (--precision); env.backend is a tag variant_of drops.
CONTEXT_KEYS = ("precision",)
# How the protocol's outcomes read for a variant (arm a) against its base (arm b; "{base}" is
# "default" or "base").
OUTCOMES = {"a better": "variant higher", "b better": "{base} higher", "equivalent": "equivalent",
            "undecided": "no difference found", "too few trials": "not tested"}


@dataclass
class Judged:
    """A variant beside its base: per-trial ``final`` (tail mean), ``curve`` (mean over the curve) and
    ``last`` (single last evaluation) scores ``(n,)`` of each arm (variant first; empty where there are
    none), where they were read (``at``), and the test of the finals (``comparison``, Holm-adjusted over
    ``family`` variants of the preset) and of the last evaluations (``last_comparison``); or ``missing``."""

    final: list[np.ndarray]
    curve: list[np.ndarray]
    last: list[np.ndarray]
    at: str
    base: str
    comparison: Comparison | None = None
    last_comparison: Comparison | None = None
    missing: str | None = None
    family: int = 0
    test: dict[str, float | int | str | None] = field(default_factory=dict)

    @property
    def outcome(self) -> str:
        if self.comparison is None:
            return "not judged"
        word = "default" if self.base == DEFAULT_VARIANT else "base"
        return OUTCOMES.get(self.comparison.outcome, self.comparison.outcome).format(base=word)

    @property
    def verdict(self) -> str:
        comp, last = self.comparison, self.last_comparison
        if comp is None or last is None:
            return f"not judged: {self.missing}"
        if comp.outcome == TOO_FEW:
            return comp.text
        power = "" if comp.n_for_power is None or self.outcome != OUTCOMES["undecided"] else (
            f"; {comp.n_for_power} trials per arm for 80% power at this effect")
        return (f"{self.outcome}: {comp.text}, Holm-adjusted p = {comp.p_adjusted:.2g} over the {self.family} "
                f"tested variant{'' if self.family == 1 else 's'} of the preset{power}; single last evaluation "
                f"{fmt(last.mean_a)} vs {fmt(last.mean_b)}, {last.text}")


@dataclass
class Variant:
    """One ``<preset>/<variant>`` and its base's runs (:func:`base_of`) it is compared with; curves
    are None for a runner that logs no evaluation returns."""

    preset: str
    exp: Experiment
    base: Experiment
    curves: Curves | None
    base_curves: Curves | None

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


def base_of(variant: str) -> str:
    """The variant a (collector) variant overrides: its :data:`CONTEXT_KEYS` parts
    (``precision=bf16,repr.action.latent_dim=8`` -> ``precision=bf16``); the default where those
    are none or all of it."""
    parts = variant.split(",")
    context = [part for part in parts if part.split("=", 1)[0].lstrip("+~") in CONTEXT_KEYS]
    return ",".join(context) if context and len(context) < len(parts) else DEFAULT_VARIANT


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
    """``preset/variant`` and its base, with their return curves where the runner logs any."""
    base = base_of(variant)
    exp, base_exp = runs.experiment(preset, variant), runs.experiment(preset, base)
    runner = exp.cfg("runner")
    if runner not in RUNNERS or not RUNNERS[runner].trains_policy:
        return Variant(preset, exp, base_exp, None, None)
    return Variant(preset, exp, base_exp, load_curves(runs, exp, variant, x_axis),
                   load_curves(runs, base_exp, base, x_axis) if base_exp.trials else None)


def judge_preset(runs: Runs, variants: list[Variant], settings: ClaimSettings) -> list[Judged]:
    """Each of one preset's variants judged against its base; the tested ones are one Holm family,
    each decided at its adjusted p."""
    judged = [judge(runs, variant, settings) for variant in variants]
    tested = [j for j in judged if j.comparison is not None and j.comparison.outcome != TOO_FEW]
    for one, p in zip(tested, holm([j.comparison.p for j in tested if j.comparison is not None])):
        one.comparison, one.family = adjust(one.comparison, float(p)), len(tested)
        one.test.update(p_adjusted=float(p), holm_family=len(tested), outcome_adjusted=one.comparison.outcome)
    return judged


def judge(runs: Runs, variant: Variant, settings: ClaimSettings) -> Judged:
    """The variant's scores beside its base's, and the test of their final returns where one budget
    and finished trials of both allow it (before any family correction); otherwise each arm's own
    scores and what is missing."""
    own = [c for c in (variant.curves, variant.base_curves) if c is not None]
    missing = _missing(variant)
    if missing is None:
        try:
            pair = matched(*own, runs=runs)
        except NotJudged as err:
            missing = str(err)
        else:
            return _tested(pair, variant, settings)
    arms = [matched_or_none(c) for c in own]
    scores = [_scores(a.values[0], settings) if a is not None else None for a in arms]
    empty = (np.zeros(0),) * 3
    final, curve, last = zip(*[s or empty for s in scores], *[empty] * (2 - len(scores)))
    return Judged(list(final), list(curve), list(last), _at("each arm on its own evaluations", arms, settings),
                  variant.base.variant, missing=missing)


def matched_or_none(curves: Curves) -> Matched | None:
    """One arm's finished trials on the evaluations all of them reach; None when none finished."""
    try:
        return matched(curves)
    except NotJudged:
        return None


def _at(where: str, arms: list[Matched | None], settings: ClaimSettings) -> str:
    """Where the arms were read, and how many evaluations "final" averaged where fewer than ``final_tail``."""
    tail = min([settings.final_tail, *(len(a.grid) for a in arms if a is not None)])
    return where if tail == settings.final_tail else f"{where}; final over the last {tail} evaluations"


def _missing(variant: Variant) -> str | None:
    """What keeps the variant from a test against its base (None: nothing, so far)."""
    base = f"{variant.preset}/{variant.base.variant}"
    if variant.curves is None:
        return f"the {variant.exp.cfg('runner') or 'unknown'} runner logs no evaluation returns"
    if not variant.curves.n:
        return "no evaluation returns of the variant"
    if not variant.base.trials or variant.base_curves is None or not variant.base_curves.n:
        return f"no runs of the {'default' if variant.base.variant == DEFAULT_VARIANT else 'base'} ({base})"
    if variant.exp.budget != variant.base.budget:
        return (f"the variant ran at budget {variant.exp.budget}, its base ({base}) at {variant.base.budget}: "
                f"run both at one budget")
    return None


def _scores(values: np.ndarray, settings: ClaimSettings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One arm's final (tail mean), curve-mean and last-evaluation scores ``(n,)`` of ``(n, P)`` returns."""
    return tail_mean(values, settings.final_tail), values.mean(axis=1), values[:, -1]


def _tested(pair: Matched, variant: Variant, settings: ClaimSettings) -> Judged:
    """Both arms on their common evaluations, the final returns tested (variant = arm a). The protocol's
    p is two-sided whatever its ``direction``, which only names the arm found higher: "greater" reads a
    significant difference as "a better" when the variant's mean is the higher, "b better" otherwise."""
    final, curve, last = zip(*[_scores(v, settings) for v in pair.values])
    comparison, last_comparison = (compare_arms(a, b, direction="greater", alpha=settings.alpha,
                                                min_n=settings.min_n) for a, b in (final, last))
    at = _at(pair.at, [pair], settings)
    test = {"test": comparison.test, "statistic": comparison.statistic, "p": comparison.p,
            "n_for_power": comparison.n_for_power, "protocol_outcome": comparison.outcome,
            "p_last": last_comparison.p, "protocol_outcome_last": last_comparison.outcome}
    return Judged(list(final), list(curve), list(last), at, variant.base.variant, comparison, last_comparison,
                  test=test)
