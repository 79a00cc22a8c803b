"""A profile plan's totals: trials to run, trials recorded, estimated compute and the rates never
measured. One place, read by the dry run's table (``reproduce.format_plan``) and by the README's
profile table (``plls_bench.report.profile_costs``), so the two cannot disagree."""
from __future__ import annotations

from dataclasses import dataclass

from plls_bench.pipeline.plan import PresetPlan


@dataclass(frozen=True)
class PlanTotals:
    trials: int                   # every trial of the plan
    pending: int                  # trials still to run
    recorded: int                 # trials a committed record holds done
    seconds: float                # estimated compute of the pending trials (unmeasured rates count 0)
    missing_rates: tuple[str, ...]  # rate keys with no measured rate, left out of ``seconds``


def plan_totals(plans: list[PresetPlan]) -> PlanTotals:
    """The totals over ``plans`` (``plan_profile``'s or ``plan_sweep``'s)."""
    return PlanTotals(trials=sum(len(p.trials) for p in plans), pending=sum(len(p.pending) for p in plans),
                      recorded=sum(p.recorded for p in plans), seconds=sum(p.seconds or 0.0 for p in plans),
                      missing_rates=tuple(sorted({key for p in plans for key in p.missing_rates})))
