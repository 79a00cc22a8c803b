"""What an undecided comparison row says it would cost to decide (plls_bench/report/claims/costs.py):
each arm from its own count up to the target, at each arm's own rate."""
from __future__ import annotations

from plls_bench.report.claims.costs import MoreTrials, more_trials, trial_seconds


def test_each_arm_is_costed_from_its_own_count_at_its_own_rate() -> None:
    more = MoreTrials(target=7, more=(4, 2), per_trial_s=(3600.0, 1800.0))
    assert more.seconds == 4 * 3600 + 2 * 1800
    assert more.text(("a", "b"), "the planned 7") == (
        "to the planned 7 per arm: 4 + 2 more trials, about 5.0 CPU-hours by the dry run's rates "
        "(results/tables/power.md)")


def test_an_arm_without_a_measured_rate_is_named_not_costed() -> None:
    more = MoreTrials(target=5, more=(2, 2), per_trial_s=(3600.0, None))
    assert more.seconds is None
    assert more.text(("a", "b"), "the planned 5") == (
        "to the planned 5 per arm: 2 + 2 more trials (no measured rate for b)")


def test_the_dry_run_s_rates_cost_a_cheap_and_an_expensive_arm_apart() -> None:
    cheap, cnn = trial_seconds("carracing_plls_ppo", "quick"), trial_seconds("carracing_ppo", "quick")
    assert cheap and cnn and cnn > 5 * cheap  # a CNN PPO trial is update-bound on a CPU; the latent arm is not
    more = more_trials("carracing_plls_ppo", "carracing_ppo", "quick", (3, 5), 5)
    assert more.more == (2, 0) and more.seconds == 2 * cheap
