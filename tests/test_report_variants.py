"""The variants view: every ``<preset>/<variant>`` run dir found is listed in the README, gets a row of
``tables/variants`` (tested against the preset's default under the declared protocol only at one budget
and enough trials) and a curve in ``figures/variants_<preset>``; checked on hand-built runs, and (slow)
on a two-variant smoke override run through ``reproduce``."""
from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from plls_bench.report import render_all
from plls_bench.report.collect import IdStatus, verify_outputs
from plls_bench.report.evidence.variant_arms import variant_of
from tests.synthetic_runs import finish, make_run, write_eval
from tests.test_reproduce import reproduce

PRESET = "mountaincar_plls_ppo"


def arm(runs: Path, variant: str, finals: list[float], budget: str = "quick") -> None:
    """One finished trial per entry of ``finals``: flat at -50, then at its final return."""
    overrides = () if variant == "default" else (variant,)
    for seed, final in enumerate(finals):
        run, cfg = make_run(runs, PRESET, seed, budget, f"budget.trials={len(finals)}", *overrides, variant=variant)
        iterations = [0, 2, 4]
        write_eval(run, cfg, iterations, [[-50.0, -50.0] if i < 4 else [final, final] for i in iterations])
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
    assert (higher["outcome"], higher["n_variant"], higher["n_default"]) == ("variant higher", 5, 5)
    assert higher["p"] < 0.05 and higher["final_variant_mean"] == 102.0 and higher["final_default_mean"] == 2.0
    assert same["outcome"] == "no difference found" and same["p"] == 1.0
    assert higher["curve_variant_mean"] == pytest.approx((-50.0 * 2 + 102.0) / 3)
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
    assert other_budget["verdict"] == ("not judged: the variant ran at budget smoke, the default at quick: "
                                       "run both at one budget")
    assert other_budget["compared"] == "each arm at its own last evaluation"
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
    assert (table["n_variant"] == 1).all() and (table["n_default"] == 1).all()
    drawn = pd.read_csv(out / "figures" / f"variants_{PRESET}.csv")
    assert set(drawn["series"]) == {"default", "repr.action.latent_dim=4", "repr.action.latent_dim=8"}
    index = json.loads((out / "index.json").read_text())
    status = IdStatus(**next(row for row in index["ids"] if row["id"] == "variants"))
    assert verify_outputs(out, {"variants": status}) == [] and f"figures/variants_{PRESET}.png" in status.files
    assert not (runs.parent / "records").exists(), "a smoke variant is never recorded"
