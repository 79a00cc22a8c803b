"""The declared decision protocol's pieces (plls_bench/report/evidence/protocol.py, docs/verdicts.md) against
independent computations, the claims' settings file rejecting a typo, a comparison row without its
settings and an anchor without its declared dispersion by name, and the rows that say
why they cannot be read: neither arm solves the task; an arm mixes commits and devices."""
from __future__ import annotations

import itertools
import math
import re
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from plls_bench.report.claims.claims_table import read_claims, reading_summary
from plls_bench.report.claims.levels import least_trials, median_interval
from plls_bench.report.collect import PAPER_DIR
from plls_bench.report.evidence.claim_settings import load_settings
from plls_bench.report.evidence.protocol import (
    A_BETTER,
    EQUIVALENT,
    UNDECIDED,
    compare_arms,
    holm,
    permutation_p,
    planned_n,
    t_interval,
    welch,
)
from plls_bench.report.evidence.verdicts import NOT_MADE, NOT_RUN, NOT_SOLVED
from tests.synthetic_runs import set_starts
from tests.test_report_matched import arm, claims, row


def test_permutation_p_is_the_exact_permutation_test_of_welch_s_t() -> None:
    rng = np.random.default_rng(0)
    a, b = rng.normal(0.0, 1.0, 5), np.array([0.3, 0.3, 1.9, 2.2, 0.3, 3.0])  # ties in b
    pooled, observed = np.concatenate([a, b]), abs(stats.ttest_ind(a, b, equal_var=False).statistic)
    splits = [np.isin(np.arange(11), chosen) for chosen in itertools.combinations(range(11), 5)]
    beyond = [abs(stats.ttest_ind(pooled[m], pooled[~m], equal_var=False).statistic) >= observed * (1 - 1e-9)
              for m in splits]  # the share of the 462 splits whose |t| reaches the observed one
    assert permutation_p(a, b) == pytest.approx(np.mean(beyond))
    assert permutation_p(np.arange(5.0), np.arange(5.0) + 10) == pytest.approx(2 / 252)  # the two extreme splits
    t, df, p = welch(a, b)
    reference = stats.ttest_ind(a, b, equal_var=False)
    assert (t, p) == pytest.approx((reference.statistic, reference.pvalue))


def test_holm_steps_down_and_leaves_untested_rows_out() -> None:
    # sorted 0.005, 0.01, 0.03, 0.04 over m = 4: 4 x 0.005, 3 x 0.01, 2 x 0.03, then max(0.06, 1 x 0.04)
    assert holm([0.01, 0.04, 0.03, math.nan, 0.005]) == pytest.approx([0.03, 0.06, 0.06, math.nan, 0.02], nan_ok=True)


def test_compare_arms_reads_direction_and_equivalence() -> None:
    low, high = [1.0, 2.0, 3.0, 4.0, 5.0], [11.0, 12.0, 13.0, 14.0, 15.0]
    assert compare_arms(low, high, direction="less").outcome == A_BETTER
    assert compare_arms(high, low, margin=1.0).outcome == A_BETTER
    assert compare_arms([1.0, 2.0, 3.0, 4.0, 5.1], [1.0, 2.0, 3.0, 4.0, 5.0], margin=3.0).outcome == EQUIVALENT
    assert compare_arms([1.0, 2.0, 3.0, 4.0, 5.1], [1.0, 2.0, 3.0, 4.0, 5.0]).outcome == UNDECIDED
    row_ = compare_arms(high, low)
    assert row_.text == ("Welch t = 10.00, p = 0.0079 (the larger of permutation 0.0079 and "
                         f"t-distribution {row_.p_welch:.2g})")
    # spreads 100 times apart: every split but the observed one and its mirror is less extreme (p = 2 / 252),
    # while the t distribution, with about 4 df, is not so sure; the decision reads the larger p
    unequal = compare_arms([1.0, 5.0, 9.0, 2.0, 12.0], [0.05, -0.05, 0.0, 0.01, -0.01])
    assert unequal.p_permutation == pytest.approx(2 / 252)
    assert unequal.p == unequal.p_welch == pytest.approx(0.0496, abs=1e-4)
    with pytest.raises(ValueError, match="direction must be one of"):
        compare_arms(low, high, direction="up")


def test_planned_n_and_intervals_match_textbook_values() -> None:
    assert planned_n(1.0, 1.0, 1.0) == 17  # d = 1: 17 per arm for 80% at alpha 0.05 (noncentral t)
    assert planned_n(0.0, 1.0, 1.0) is None
    # a huge effect still needs the n at which the p can reach the level: 6 + 6 at Holm's 0.05 / 16
    assert planned_n(100.0, 1.0, 1.0) == 5 and planned_n(100.0, 1.0, 1.0, alpha=0.05 / 16) == 6
    low, high = t_interval([1.0, 2.0, 3.0])
    assert (low, high) == pytest.approx((2 - 4.302653 / math.sqrt(3), 2 + 4.302653 / math.sqrt(3)))
    assert least_trials(0.95) == 6 and median_interval([1.0, 2.0, 3.0], 0.95) is None
    assert median_interval([5.0, 1.0, 4.0, 2.0, 3.0, math.inf], 0.95) == (1.0, math.inf, 1 - 2 / 64)


def _paper_copy(tmp_path: Path) -> Path:
    paper = tmp_path / "paper"
    shutil.copytree(PAPER_DIR, paper)
    return paper


def test_a_typo_in_claims_yaml_fails_naming_the_key(tmp_path: Path) -> None:
    paper = _paper_copy(tmp_path)
    text = (paper / "claims.yaml").read_text()
    (paper / "claims.yaml").write_text(text.replace("{margin: 50.0, planned_n: 8,", "{marign: 50.0, planned_n: 8,"))
    with pytest.raises(ValueError, match=r"comparisons\.PL-LS with PPO beats PPO on CarRacing \(final return\): keys "
                                         r"must be .*wrong or missing: margin, marign"):
        read_claims(paper)
    (paper / "claims.yaml").write_text(text.replace('"PPO has the larger variance on CarRacing":',
                                                    '"PPO has the larger varianse on CarRacing":'))
    with pytest.raises(ValueError, match="comparisons: not a claim of claims.csv: 'PPO has the larger varianse"):
        read_claims(paper)


def test_a_comparison_row_without_its_settings_is_refused_naming_it(tmp_path: Path) -> None:
    paper = _paper_copy(tmp_path)
    text = (paper / "claims.yaml").read_text()
    entry = ('  "PPO has the larger variance on CarRacing":\n'
             "    {margin: null, planned_n: 10, primary: true, paper_n: 10}\n")
    assert entry in text
    (paper / "claims.yaml").write_text(text.replace(entry, ""))
    with pytest.raises(ValueError, match=r"comparisons: no entry for the std_gap row 'PPO has the larger variance on "
                                         r"CarRacing' \(every comparison row declares margin, planned_n"):
        read_claims(paper)


def test_every_published_anchor_declares_its_dispersion_and_threshold(tmp_path: Path) -> None:
    read_claims(PAPER_DIR)  # the repository's own rows pass: every final return with a ± is declared
    paper = _paper_copy(tmp_path)
    pixel = "Suite pixel SAC reaches CURL's Pixel SAC on cheetah-run at 100k env steps (final return)"
    yaml_text, csv_text = (paper / "claims.yaml").read_text(), (paper / "claims.csv").read_text()
    entry = f'  "{pixel}":\n    {{dispersion: seeds, n: 10}}'
    assert entry in yaml_text and ",197,15,at_least,182," in csv_text
    (paper / "claims.yaml").write_text(yaml_text.replace(entry, ""))
    with pytest.raises(ValueError, match=f"anchors: no entry for {re.escape(repr(pixel))}: its published ±"):
        read_claims(paper)
    (paper / "claims.yaml").write_text(yaml_text.replace(entry, entry.replace("seeds, n: 10", "episodes, n: null")))
    with pytest.raises(ValueError, match="threshold 182, but 197 ± 15 over episodes implies 197"):
        read_claims(paper)  # an SD over episodes says nothing about seeds: the published mean is the bar
    (paper / "claims.yaml").write_text(yaml_text)
    (paper / "claims.csv").write_text(csv_text.replace(",197,15,at_least,182,", ",197,15,at_least,190,"))
    with pytest.raises(ValueError, match="threshold 190, but 197 ± 15 over seeds implies 182"):
        read_claims(paper)


def test_only_decided_readings_that_differ_count_as_depending_on_the_reading() -> None:
    settings = replace(load_settings(PAPER_DIR, [c["claim"] for c in read_claims(PAPER_DIR)]), readings=[
        ("exploration", ("a", "b")), ("exploration", ("c", "d")), ("mode", ("e", "f")), ("mode", ("g", "h", "i"))])
    final = {name: (verdict, "") for name, verdict in {
        "a": "reproduced", "b": "not reproduced",  # decided both ways: depends
        "c": NOT_MADE, "d": NOT_RUN,  # nothing decided yet: not comparable, not a disagreement
        "e": "inconclusive", "f": "inconclusive",  # decided, agreeing
        "g": "reproduced", "h": NOT_SOLVED, "i": NOT_RUN}.items()}  # one decided: not comparable
    assert reading_summary(settings, final) == (
        "1 of 4 claims read more than one way depend on the reading, two readings decided (reproduced, not "
        "reproduced, inconclusive) and differing (exploration 1 of 2, mode 0 of 2); 2 are not yet comparable, "
        "fewer than two readings decided")


def test_a_comparison_where_neither_arm_solves_the_task_is_not_made(tmp_path: Path) -> None:
    # MountainCar's solve criterion is 90 (claims.yaml, solved_at): returns near 0 never reach the flag
    # (the gSDE row: it plans the paper's 7 trials per arm, claims.yaml)
    text = "PL-LS with PPO beats PPO on MountainCar (final return) [gSDE"
    arm(tmp_path / "stuck", "mountaincar_plls_ppo_gsde", 7, [0, 10, 20], lambda seed, i: -1e-4 * (seed + 1))
    arm(tmp_path / "stuck", "mountaincar_ppo_gsde", 7, [0, 10, 20], lambda seed, i: -2e-4 * (seed + 1))
    stuck = row(claims(tmp_path / "stuck", tmp_path / "out1"), text)
    assert stuck["verdict"] == "not made: neither arm solves the task"
    assert stuck["reason"].startswith("no trial of either arm reaches mountaincar's solve criterion 90")
    arm(tmp_path / "solves", "mountaincar_plls_ppo_gsde", 7, [0, 10, 20], lambda seed, i: 93.0 + seed)
    arm(tmp_path / "solves", "mountaincar_ppo_gsde", 7, [0, 10, 20], lambda seed, i: -2e-4 * (seed + 1))
    assert row(claims(tmp_path / "solves", tmp_path / "out2"), text)["verdict"] == "reproduced"


def test_an_arm_that_mixes_commits_and_devices_says_so(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "carracing_plls_ppo", 5, [0, 32, 64], lambda seed, i: 200.0 + seed)
    arm(runs, "carracing_ppo", 5, [0, 32, 64], lambda seed, i: 50.0 + seed)
    for seed in range(5):
        first = ("cpu", "a" * 40) if seed < 2 else ("cuda:0", "b" * 40)
        later = [("cpu", "c" * 40)] if seed == 4 else []
        set_starts(runs / "carracing_ppo" / "default" / f"seed={seed}", first, *later)
    table = claims(runs, tmp_path / "out")
    # seed 4 stopped on the GPU and resumed on a CPU at a later commit: the row names both
    mix = ("; carracing_ppo pools seeds 0, 1 (cpu, aaaaaaa); seeds 2, 3 (cuda, bbbbbbb); "
           "seed 4 (cuda + cpu, bbbbbbb + ccccccc)")
    assert row(table, "PL-LS with PPO beats PPO on CarRacing (final return)")["budget"].endswith(mix)
    assert row(table, "PPO not converged by 120,000 iterations on CarRacing")["budget"].endswith(mix)  # convergence
