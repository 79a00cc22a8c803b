"""The bf16-vs-fp32 null comparison (plls_bench/validation/precision.py): its distances
and pass rule on synthetic outputs, its input checks, and one end-to-end run at a tiny size."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from plls_bench.validation.precision import (
    DBC_MEASURES,
    PPO_MEASURES,
    compare,
    gaussian_kl,
    main,
    mean_abs,
    passes,
    relative_l2,
)


def test_gaussian_kl_is_zero_for_equal_and_known_for_shifted_means() -> None:
    mean, std = np.zeros((5, 3)), np.ones((5, 3))
    assert gaussian_kl(mean, std, mean, std) == 0.0
    # unit variances, means 1 apart in each of 3 dims: KL = 1/2 per dim either way
    assert gaussian_kl(mean, std, mean + 1.0, std) == pytest.approx(1.5)
    # symmetrised: swapping the arguments gives the same value
    wide = 2.0 * std
    assert gaussian_kl(mean, std, mean, wide) == pytest.approx(gaussian_kl(mean, wide, mean, std))
    assert gaussian_kl(mean, std, mean, wide) > 0.0


def test_mean_abs_and_relative_l2() -> None:
    a = np.array([[3.0, 4.0], [0.0, 5.0]])
    assert mean_abs(a, a + 0.5) == pytest.approx(0.5)
    assert relative_l2(a, a) == 0.0
    assert relative_l2(a, 2 * a) == pytest.approx(5.0 / 7.5)  # |a_n| = 5, |2 a_n| = 10


@pytest.mark.parametrize("same, cross, expected", [
    ([1e-3, 2e-3, 3e-3], [5e-3, 4e-3, 6e-3], True),    # bf16 well inside the order noise
    ([1e-3, 4e-3, 3e-3], [5e-3, 4e-3, 6e-3], True),    # equal to the smallest: "no larger" passes
    ([1e-3, 2e-3, 4.5e-3], [5e-3, 4e-3, 6e-3], False),  # one bf16 distance above the smallest order distance
    ([1e-1, 2e-1, 3e-1], [5e-3, 4e-3, 6e-3], False),   # bf16 far outside the noise
    ([1e-3, float("nan"), 1e-3], [5e-3, 4e-3, 6e-3], False),
    ([], [5e-3], False),
])
def test_the_pass_rule(same: list[float], cross: list[float], expected: bool) -> None:
    assert passes(same, cross) is expected


def _synthetic_ppo(bf16_shift: float, k: int = 3, n: int = 50, seed: int = 0) -> dict:
    """PPO outputs of K fp32 orders (each its own random offset of scale 0.1) and bf16 twins off by ``bf16_shift``."""
    rng = np.random.default_rng(seed)
    base = {"mean": rng.normal(size=(n, 3)), "std": np.full((n, 3), 0.5), "value": rng.normal(size=n)}

    def moved(out: dict, scale: float) -> dict:
        return {"mean": out["mean"] + scale * rng.normal(size=(n, 3)), "std": out["std"],
                "value": out["value"] + scale * rng.normal(size=n)}

    fp32 = [moved(base, 0.1) for _ in range(k)]
    return {"initial": base, "initial_bf16": moved(base, 1e-4), "fp32": fp32, "fp32_repeat": fp32[0],
            "bf16": [moved(out, bf16_shift) for out in fp32]}


@pytest.mark.parametrize("bf16_shift, expected", [(1e-3, True), (1.0, False)])
def test_compare_applies_the_rule_to_every_measure(bf16_shift: float, expected: bool) -> None:
    result = compare(_synthetic_ppo(bf16_shift), PPO_MEASURES)
    assert set(result) == set(PPO_MEASURES)
    for r in result.values():
        assert len(r["same_order"]) == 3 and len(r["fp32_orders"]) == 3  # K = 3 orders, 3 pairs
        assert r["repeat"] == 0.0
        assert r["passes"] is expected


def test_bad_options_are_refused_in_one_line(capsys: pytest.CaptureFixture, tmp_path: Path) -> None:
    report = str(tmp_path / "report.md")
    for argv, option in ((["--orders", "1", "--out", report], "--orders"),
                         (["--dbc-updates", "0", "--out", report], "--dbc-updates"),
                         (["--out", str(tmp_path / "report.txt")], "--out")):
        with pytest.raises(SystemExit):
            main(argv)
        assert option in capsys.readouterr().err.strip().splitlines()[-1]
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.slow
def test_end_to_end_at_a_tiny_size(tmp_path: Path, one_torch_thread: None) -> None:
    out = tmp_path / "analysis" / "precision_validation.md"
    main(["--orders", "2", "--ppo-envs", "2", "--ppo-steps", "8", "--ppo-epochs", "1", "--ppo-batch", "8",
          "--dbc-transitions", "20", "--dbc-updates", "2", "--dbc-batch", "8", "--heldout", "8", "--out", str(out)])
    text, report = out.read_text(), json.loads(out.with_suffix(".json").read_text())
    assert "Command: `python -m plls_bench.validation.precision --orders 2" in text
    assert "## PPO CNN (`carracing_ppo`): bf16" in text and "## DBC (`cheetah_dbc`): bf16" in text
    assert "smaller than the issue's" in text and "bf16 on this CPU:" in text
    for key, measures in (("ppo", PPO_MEASURES), ("dbc", DBC_MEASURES)):
        assert set(report[key]["result"]) == set(measures)
        for r in report[key]["result"].values():
            assert len(r["same_order"]) == 2 and len(r["fp32_orders"]) == 1
            assert r["repeat"] == 0.0           # the same order twice gives the same network
            assert min(r["update"]) > 0.0       # the update moved it
            assert r["passes"] == passes(r["same_order"], r["fp32_orders"])
    assert report["ppo"]["sizes"] == {"envs": 2, "steps": 8, "epochs": 1, "batch": 8, "heldout": 8}
    assert report["dbc"]["sizes"] == {"transitions": 20, "updates": 2, "batch": 8, "heldout": 8}
