"""Throughput rate keys per backend and precision: the one suffix builder (``rates.rate_suffix``),
the keys ``bench/throughput.py`` measures, and the plan's lookup (nothing here is timed)."""
from __future__ import annotations

from pathlib import Path

import pytest

from bench.throughput import MEASURES, rate_keys
from plls_bench.pipeline.plan import plan_profile
from plls_bench.pipeline.rates import rate_suffix
from plls_bench.pipeline.runner_registry import SPECS
from tests.conftest import compose_preset

TRAIN, EVAL = "train/carracing_ppo", "eval/carracing_ppo"


@pytest.mark.parametrize("backend, precision, full, env_only, precision_only", [
    ("gymnasium", "fp32", "", "", ""),
    ("envpool", "fp32", "@envpool", "@envpool", ""),
    ("gymnasium", "bf16", "@bf16", "", "@bf16"),
    ("envpool", "bf16", "@envpool@bf16", "@envpool", "@bf16"),
])
def test_the_suffix_tags_backend_then_precision_where_each_applies(
        runs_dir: Path, backend: str, precision: str, full: str, env_only: str, precision_only: str) -> None:
    cfg = compose_preset("carracing_ppo", runs_dir, "budget=quick", f"env.backend={backend}",
                         f"precision={precision}")
    assert rate_suffix(cfg) == full
    assert rate_suffix(cfg, precision_bound=False) == env_only
    assert rate_suffix(cfg, env_bound=False) == precision_only


def test_bench_measures_the_keys_the_plan_looks_up(runs_dir: Path) -> None:
    cfg = compose_preset("carracing_ppo", runs_dir, "budget=quick", "env.backend=envpool", "precision=bf16")
    assert rate_keys(cfg) == [f"{TRAIN}@envpool@bf16", f"{EVAL}@envpool@bf16"]
    vs = compose_preset("carracing_vs", runs_dir, "budget=quick", "precision=bf16")
    assert rate_keys(vs) == ["repr_state/carracing@bf16"]  # V_s has conv trunks
    va = compose_preset("carracing_va", runs_dir, "budget=quick", "precision=bf16")
    assert rate_keys(va) == ["repr_action/carracing"]  # V_a is an MLP: one rate for both


def test_every_runner_names_a_measurement_the_bench_has() -> None:
    assert {spec.measure for spec in SPECS} <= set(MEASURES)


def test_a_bf16_plan_uses_bf16_rates_and_never_falls_back_to_fp32(runs_dir: Path) -> None:
    fp32_rates = {f"{TRAIN}@envpool": 100.0, f"{EVAL}@envpool": 1000.0}
    quick = ["carracing_ppo"]
    fp32 = plan_profile("quick", str(runs_dir), only=quick, rates=fp32_rates, overrides=(), count_records=False)[0]
    assert fp32.seconds is not None and not fp32.missing_rates
    bf16 = plan_profile("quick", str(runs_dir), only=quick, rates=fp32_rates, overrides=("precision=bf16",),
                        count_records=False)[0]
    assert bf16.seconds is None, "no bf16 rate: the estimate must say so, not use the fp32 one"
    assert bf16.missing_rates == [f"{EVAL}@envpool@bf16", f"{TRAIN}@envpool@bf16"]
    assert all(t.cfg.precision == "bf16" and t.run_dir.parent.name == "precision=bf16,env.backend=envpool"
               for t in bf16.trials)
    # half the fp32 rates: twice the fp32 estimate
    both = {**fp32_rates, **{f"{key}@bf16": rate / 2 for key, rate in fp32_rates.items()}}
    costed = plan_profile("quick", str(runs_dir), only=quick, rates=both, overrides=("precision=bf16",),
                          count_records=False)[0]
    assert costed.seconds == pytest.approx(2 * fp32.seconds)


@pytest.mark.parametrize("clock, train, acting, unit", [
    ("cpu", 40.0, 400.0, "env steps per CPU-s"),
    ("wall", 20.0, 200.0, "env steps/s"),
])
def test_ppo_rates_come_from_the_chosen_clock(runs_dir: Path, monkeypatch: pytest.MonkeyPatch, clock: str,
                                              train: float, acting: float, unit: str) -> None:
    """The dry run adds rates up as CPU-hours: ``--clock cpu`` must hand it the per-CPU-second
    figures of the measurement, ``--clock wall`` the wall-clock ones (the measurement is stubbed)."""
    import bench.throughput as throughput

    measured = {"sps": 20.0, "rollout_sps": 200.0, "cpu_sps": 40.0, "rollout_cpu_sps": 400.0}
    monkeypatch.setattr(throughput, "prepare_representations", lambda cfg: None)
    monkeypatch.setattr(throughput.ppo_throughput, "measure", lambda *args, **kwargs: measured)
    cfg = compose_preset("carracing_ppo", runs_dir, "budget=quick")
    args = throughput.argparse.Namespace(clock=clock, ppo_steps=125, budget="quick", runs=str(runs_dir),
                                         ppo_iterations=1)
    assert MEASURES["ppo_iterations"].measure(cfg, rate_keys(cfg), args, ()) == [(train, unit), (acting, unit)]


def test_dbc_rates_add_acting_and_update_time_on_the_chosen_clock(
        runs_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import bench.throughput as throughput

    measured = {"env_sps": 100.0, "update_s": 2.0, "env_cpu_sps": 200.0, "cpu_s": 1.0}
    monkeypatch.setattr(throughput, "prepare_representations", lambda cfg: None)
    monkeypatch.setattr(throughput.dbc_throughput, "measure", lambda *args, **kwargs: measured)
    cfg = compose_preset("cheetah_dbc", runs_dir, "budget=quick")
    args = throughput.argparse.Namespace(clock="cpu", budget="quick", runs=str(runs_dir), dbc_steps=1, dbc_updates=1)
    (train, unit), (acting, _) = MEASURES["dbc_steps"].measure(cfg, rate_keys(cfg), args, ())
    # one CPU-second update per action_repeat env steps, plus 1/200 s of acting per env step
    assert unit == "env steps per CPU-s" and acting == 200.0
    assert train == pytest.approx(1.0 / (1.0 / 200.0 + 1.0 / cfg.env.action_repeat))


def test_compare_writes_ratios_beside_the_table_and_leaves_the_table_alone(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--compare`` on another machine: each measured key beside the table's rate with their ratio,
    a wall-clock table row flagged, a key the table lacks named; ``bench/throughput.json`` unchanged."""
    import json

    import bench.throughput as throughput

    table = tmp_path / "throughput.json"
    rates = {"train/a": {"value": 600.0, "unit": "env steps per CPU-s", "date": "d", "machine": "xeon"},
             "train/b": {"value": 6000.0, "unit": "env steps/s", "date": "d", "machine": "old"}}
    table.write_text(json.dumps({"rates": rates}))
    before = table.read_bytes()
    written: dict[str, str] = {}
    monkeypatch.setattr(throughput, "THROUGHPUT_FILE", table)
    monkeypatch.setattr(throughput, "write_section", lambda section, text: written.update({section: text}))
    measured = {"train/a": (300.0, "env steps per CPU-s"), "train/b": (2400.0, "env steps per CPU-s"),
                "train/c": (5.0, "env steps per CPU-s")}
    monkeypatch.setattr(throughput, "preset_rates", lambda preset, args: measured)
    assert throughput.main(["--presets", "p", "--compare"]) == 0
    assert table.read_bytes() == before
    text = written[throughput.compare_section("gymnasium")]
    assert "| `train/a` | 300 env steps per CPU-s | 600 env steps per CPU-s | 0.50 | d, xeon |" in text
    assert "| 0.40 (clocks differ) |" in text
    assert "| `train/c` | 5 env steps per CPU-s | (not in the table) |" in text
