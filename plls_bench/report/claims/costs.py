"""What more trials of a comparison claim's arms cost, by the dry run's rates (``bench/throughput.json``
through :mod:`plls_bench.pipeline.plan`): the power table's cost columns, and the note a comparison row
carries when it is not decided yet (how many more trials per arm its planned n asks for, and their
CPU-hours), so an expensive arm's row says what a decisive verdict would cost."""
from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from plls_bench.pipeline.plan import plan_profile
from plls_bench.pipeline.rates import load_rates
from plls_bench.report.evidence.claim_settings import ClaimSettings
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.protocol import TOO_FEW, Comparison
from plls_bench.report.evidence.verdicts import INCONCLUSIVE, INTERIM, NOT_RUN

POWER_TABLE = "results/tables/power.md"


@cache
def trial_seconds(experiment: str, budget: str, runs_dir: str | None = None) -> float | None:
    """The dry run's compute for one more whole trial of ``experiment`` at ``budget``: the cheapest
    pending trial (its shared artifacts are costed in the first trial only, so the cheapest is the
    marginal one), a trial that resumes from a checkpoint scaled up to the whole trial it is part of
    (else a nearly finished partial record would make more trials look cheap); None without a
    measured rate. ``runs_dir``: the repository's ``results/runs`` unless given."""
    if runs_dir is None:
        from plls_bench.rundirs.composition import CONF_DIR
        runs_dir = str(CONF_DIR.parent / "results" / "runs")
    plans = [p for p in plan_profile(budget, runs_dir, only=[experiment], rates=load_rates(), count_records=False)
             if p.experiment == experiment]
    seconds = [p.trial_seconds[t.seed] / t.remaining for p in plans for t in p.trials
               if t.seed in p.trial_seconds and t.remaining > 0]
    return min(seconds) if seconds and not any(p.missing_rates for p in plans) else None


@dataclass(frozen=True)
class MoreTrials:
    """More trials of each arm up to ``target`` per arm, and their compute (None: an arm has no rate)."""

    target: int
    more: tuple[int, int]
    per_trial_s: tuple[float | None, float | None]

    @property
    def seconds(self) -> float | None:
        if None in self.per_trial_s:
            return None
        return sum(k * s for k, s in zip(self.more, self.per_trial_s))  # type: ignore[misc]

    def text(self, arms: tuple[str, str], target: str) -> str:
        """"to the planned 7 per arm: 2 + 4 more trials, about 8.2 CPU-hours by the dry run's rates"
        (``target``: "the planned 7")."""
        more = f"{self.more[0]} + {self.more[1]} more trials"
        if self.seconds is None:
            missing = sorted({a for a, s in zip(arms, self.per_trial_s) if s is None})
            return f"to {target} per arm: {more} (no measured rate for {', '.join(missing)})"
        return (f"to {target} per arm: {more}, about {self.seconds / 3600:.1f} CPU-hours by the "
                f"dry run's rates ({POWER_TABLE})")


def more_trials(experiment: str, baseline: str, budget: str | None, counts: tuple[int, int],
                target: int) -> MoreTrials:
    """What running each arm (``baseline`` empty: the experiment's own other values, a sweep) from
    ``counts`` finished trials up to ``target`` costs at ``budget``."""
    arms = (experiment, baseline or experiment)
    per_trial = tuple(trial_seconds(a, budget) if budget else None for a in arms)
    more = tuple(max(target - n, 0) for n in counts)
    return MoreTrials(target, more, per_trial)  # type: ignore[arg-type]


def undecided_cost(runs: Runs, claim: dict[str, str], comp: Comparison | None, outcome: str,
                   settings: ClaimSettings) -> str | None:
    """For a comparison row not decided yet (not run for too few trials, an interim look, or inconclusive): the trials
    each arm needs to its planned n (claims.yaml), or, once there, to the n that 80% power needs at
    the observed effect, and their compute; None for any other row."""
    too_few = outcome == NOT_RUN and comp is not None and comp.outcome == TOO_FEW
    undecided = outcome in (INCONCLUSIVE, INTERIM) or too_few
    if comp is None or not undecided or claim["claim"] not in settings.comparisons or not claim["baseline"]:
        return None  # a sweep's arms are its other values, each a variant: its power row costs them
    target, label = settings.planned(claim["claim"]), "the planned {}"
    if min(comp.n_a, comp.n_b) >= target:
        if not comp.n_for_power or comp.n_for_power <= min(comp.n_a, comp.n_b):
            return None
        target, label = comp.n_for_power, "the {} that 80% power needs at the observed effect"
    budget = runs.experiment(claim["experiment"]).budget
    more = more_trials(claim["experiment"], claim["baseline"], budget, (comp.n_a, comp.n_b), target)
    return more.text((claim["experiment"], claim["baseline"] or claim["experiment"]), label.format(target))
