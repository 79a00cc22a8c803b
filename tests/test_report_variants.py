"""The variants view: every ``<preset>/<variant>`` run dir found is listed in the README, gets a row of
``tables/variants`` (tested against its base under the declared protocol and claims.yaml's settings, the
final return a tail mean, Holm over a preset's variants, only at one budget and enough trials) and a curve
in ``figures/variants_<preset>``; checked on hand-built runs, and (slow) on a two-variant smoke override
run through ``reproduce``."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from plls_bench.report import render_all
from plls_bench.report.collect import IdStatus, verify_outputs
from plls_bench.report.evidence.variant_arms import base_of, variant_of
from tests.synthetic_runs import finish, make_run, write_eval
from tests.test_reproduce import reproduce

PRESET = "mountaincar_plls_ppo"


def arm(runs: Path, variant: str, finals: list[float], budget: str = "quick",
        lasts: list[float] | None = None) -> None:
    """One finished trial per entry of ``finals``: five evaluations, two at -50, then two at its final
    return and the last at ``lasts``' entry (default: the final return again, so the tail is flat)."""
    overrides = () if variant == "default" else tuple(variant.split(","))
    for seed, final in enumerate(finals):
        run, cfg = make_run(runs, PRESET, seed, budget, f"budget.trials={len(finals)}", *overrides, variant=variant)
        last = final if lasts is None else lasts[seed]
        write_eval(run, cfg, range(5), [[v, v] for v in (-50.0, -50.0, final, final, last)])
        finish(run, cfg)


def render(runs: Path, out: Path) -> tuple[pd.DataFrame, str, IdStatus]:
    statuses = render_all(runs, out, only=["variants"])
    assert verify_outputs(out, statuses) == []
    table = pd.read_csv(out / "tables" / "variants.csv")
    return table.set_index("variant") if len(table) else table, (out / "README.md").read_text(), statuses["variants"]


def test_a_run_dir_variant_is_read_without_its_backend_tag() -> None:
    assert variant_of("repr.action.latent_dim=8,env.backend=envpool") == "repr.action.latent_dim=8"
    assert variant_of("env.backend=envpool") == variant_of("default") == "default"
    assert variant_of("a=1,b=2") == "a=1,b=2"


def test_each_variant_is_listed_tested_against_the_default_and_drawn(tmp_path: Path) -> None:
    runs, default = tmp_path / "runs", [0.0, 1.0, 2.0, 3.0, 4.0]
    arm(runs, "default", default)
    arm(runs, "repr.action.latent_dim=16", [100.0, 101.0, 102.0, 103.0, 104.0])
    arm(runs, "repr.action.latent_dim=4", list(reversed(default)))
    table, readme, status = render(runs, tmp_path / "out")
    assert list(table.index) == ["repr.action.latent_dim=4", "repr.action.latent_dim=16"]  # natural order
    higher, same = table.loc["repr.action.latent_dim=16"], table.loc["repr.action.latent_dim=4"]
    assert (higher["outcome"], higher["n_variant"], higher["n_base"], higher["base"]) == ("variant higher", 5, 5,
                                                                                         "default")
    assert higher["p"] < 0.05 and higher["final_variant_mean"] == 102.0 and higher["final_base_mean"] == 2.0
    assert same["outcome"] == "no difference found" and same["p"] == 1.0
    assert higher["curve_variant_mean"] == pytest.approx((-50.0 * 2 + 102.0 * 3) / 5)
    line = (f"- `{PRESET}` `repr.action.latent_dim=16`: 5 trials, budget quick, runs in "
            f"`{runs / PRESET / 'repr.action.latent_dim=16'}`; default: 5 trials, budget quick; vs default: "
            "variant higher: Welch t = ")
    assert line in readme and "## Variants" in readme
    figure = tmp_path / "out" / "figures" / f"variants_{PRESET}.png"
    assert f"figures/variants_{PRESET}.png" in status.files and figure.is_file()
    drawn = pd.read_csv(figure.with_suffix(".csv"))
    assert set(drawn["series"]) == {"default", "repr.action.latent_dim=4", "repr.action.latent_dim=16"}
    assert status.trials == {f"{PRESET} repr.action.latent_dim=4": 5, f"{PRESET} repr.action.latent_dim=16": 5}


def test_a_variant_is_tested_only_at_the_default_s_budget_and_with_enough_trials(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "default", [0.0, 1.0, 2.0, 3.0, 4.0])
    arm(runs, "repr.action.latent_dim=4", [5.0], budget="smoke")
    arm(runs, "repr.action.latent_dim=8", [5.0, 6.0, 7.0])
    table, readme, _ = render(runs, tmp_path / "out")
    other_budget, few = table.loc["repr.action.latent_dim=4"], table.loc["repr.action.latent_dim=8"]
    assert other_budget["verdict"] == (f"not judged: the variant ran at budget smoke, its base ({PRESET}/default) "
                                       "at quick: run both at one budget")
    assert other_budget["compared"] == "each arm on its own evaluations"
    assert other_budget["final_variant_mean"] == 5.0
    assert few["verdict"] == "not tested: needs 5 per arm, has 3 + 5" and few["outcome"] == "not tested"
    assert "vs default: not tested: needs 5 per arm, has 3 + 5" in readme


def test_a_variant_without_default_runs_says_so_and_no_variant_says_none(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "default", [0.0])
    _, readme, status = render(runs, tmp_path / "none")
    assert "No variant found: every run dir is a preset's default." in readme and status.status == "ok"
    lone = tmp_path / "lone"
    arm(lone, "repr.action.latent_dim=8", [1.0, 2.0])
    table, _, _ = render(lone, tmp_path / "out")
    assert table.loc["repr.action.latent_dim=8", "verdict"] == f"not judged: no runs of the default ({PRESET}/default)"


def test_the_final_return_is_the_protocol_s_tail_mean_and_the_last_evaluation_a_sensitivity_reading(
        tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    # The tail mean says the variant is higher, the single last evaluation says the default is.
    arm(runs, "default", [0.0, 1.0, 2.0, 3.0, 4.0], lasts=[10.0, 11.0, 12.0, 13.0, 14.0])
    arm(runs, "repr.action.latent_dim=8", [20.0, 21.0, 22.0, 23.0, 24.0], lasts=[0.0, 1.0, 2.0, 3.0, 4.0])
    table, readme, _ = render(runs, tmp_path / "out")
    row = table.loc["repr.action.latent_dim=8"]
    assert row["final_variant_mean"] == pytest.approx((2 * 22.0 + 2.0) / 3)  # claims.yaml final_tail: 3
    assert row["final_base_mean"] == pytest.approx((2 * 2.0 + 12.0) / 3)
    assert (row["last_variant_mean"], row["last_base_mean"]) == (2.0, 12.0)
    assert row["outcome"] == "variant higher" and row["protocol_outcome_last"] == "b better"
    assert "; single last evaluation 2 vs 12, Welch t = " in row["verdict"]
    md = (tmp_path / "out" / "tables" / "variants.md").read_text()
    assert "Final (mean of the last 3 evaluations): variant" in md
    drawn = (tmp_path / "out" / "figures" / f"variants_{PRESET}.csv")
    assert drawn.is_file() and "variant higher" in readme


def test_a_precision_variant_s_override_is_judged_against_its_own_precision(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "default", [0.0, 1.0, 2.0, 3.0, 4.0])
    arm(runs, "precision=bf16", [100.0, 101.0, 102.0, 103.0, 104.0])
    arm(runs, "precision=bf16,repr.action.latent_dim=8", [100.0, 101.0, 102.0, 103.0, 104.0])
    table, readme, _ = render(runs, tmp_path / "out")
    context, override = table.loc["precision=bf16"], table.loc["precision=bf16,repr.action.latent_dim=8"]
    assert (context["base"], context["outcome"]) == ("default", "variant higher")
    assert (override["base"], override["outcome"], override["final_base_mean"]) == (
        "precision=bf16", "no difference found", 102.0)
    assert (f"- `{PRESET}` `precision=bf16,repr.action.latent_dim=8`: 5 trials, budget quick, runs in "
            f"`{runs / PRESET / 'precision=bf16,repr.action.latent_dim=8'}`; base `precision=bf16`: 5 trials, "
            "budget quick; vs base: no difference found") in readme
    assert base_of("precision=bf16,repr.action.latent_dim=8") == "precision=bf16"
    assert base_of("precision=bf16") == base_of("repr.action.latent_dim=8") == "default"


def test_a_preset_s_variants_are_one_holm_family(tmp_path: Path) -> None:
    runs = tmp_path / "runs"
    arm(runs, "default", [0.0, 1.0, 2.0, 3.0, 4.0])
    arm(runs, "repr.action.latent_dim=4", [3.0, 4.0, 5.0, 6.0, 7.0])  # alone: p = 10/252, "variant higher"
    arm(runs, "repr.action.latent_dim=8", [3.0, 4.0, 5.0, 6.0, 8.0])
    table, _, _ = render(runs, tmp_path / "out")
    for row in (table.loc["repr.action.latent_dim=4"], table.loc["repr.action.latent_dim=8"]):
        assert row["p"] == pytest.approx(10 / 252) and row["protocol_outcome"] == "a better"
        assert row["p_adjusted"] == pytest.approx(2 * 10 / 252) and row["holm_family"] == 2
        assert row["outcome"] == "no difference found"
        assert f"Holm-adjusted p = {2 * 10 / 252:.2g} over the 2 tested variants of the preset" in row["verdict"]


@pytest.mark.slow
def test_a_two_variant_smoke_override_through_reproduce_shows_its_lines_rows_and_figure(tmp_path: Path) -> None:
    runs, out = tmp_path / "runs", tmp_path / "out"
    done = reproduce("--profile", "smoke", "--only", PRESET, "--override", "repr.action.latent_dim=4,8",
                     "--runs", str(runs), "--out", str(out), timeout=1800)
    assert done.returncode == 0, (done.stdout + done.stderr)[-4000:]
    for value in (4, 8):
        assert (runs / PRESET / f"repr.action.latent_dim={value}" / "seed=0" / "status.json").is_file()
        assert f"[reproduce] {PRESET} repr.action.latent_dim={value}: ok; ran 1 trial(s)" in done.stdout
    readme = (out / "README.md").read_text()
    for value in (4, 8):
        assert (f"- `{PRESET}` `repr.action.latent_dim={value}`: 1 trial, budget smoke, runs in "
                f"`{runs / PRESET / f'repr.action.latent_dim={value}'}`; default: 1 trial, budget smoke; "
                "vs default: not tested: needs 5 per arm, has 1 + 1") in readme
    table = pd.read_csv(out / "tables" / "variants.csv")
    assert list(table["variant"]) == ["repr.action.latent_dim=4", "repr.action.latent_dim=8"]
    assert (table["n_variant"] == 1).all() and (table["n_base"] == 1).all()
    drawn = pd.read_csv(out / "figures" / f"variants_{PRESET}.csv")
    assert set(drawn["series"]) == {"default", "repr.action.latent_dim=4", "repr.action.latent_dim=8"}
    index = json.loads((out / "index.json").read_text())
    status = IdStatus(**next(row for row in index["ids"] if row["id"] == "variants"))
    assert verify_outputs(out, {"variants": status}) == [] and f"figures/variants_{PRESET}.png" in status.files
    assert not (runs.parent / "records").exists(), "a smoke variant is never recorded"
