"""The results collector's command line: it lists the registry, renders one id, refuses bad input
(a bad flag, a broken paper csv) before writing anything, and runs after reproduce.sh's presets."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from plls_bench.report import ENTRIES
from plls_bench.report.__main__ import main as report_main
from plls_bench.report.collect import PAPER_DIR
from tests.conftest import REPO_ROOT
from tests.synthetic_runs import build_hand_runs


def report_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "plls_bench.report", "--no-progress", *args], cwd=REPO_ROOT,
                          env={**os.environ, "PYTHONUNBUFFERED": "1"}, capture_output=True, text=True, timeout=300)


def test_cli_lists_the_registry_and_renders_one_id(tmp_path: Path) -> None:
    listing = report_cli("--list")
    assert listing.returncode == 0 and all(f"{e.id} " in listing.stdout for e in ENTRIES)
    assert "carracing_ppo_vs, carracing_ppo_va" in listing.stdout  # Fig 20's presets
    build_hand_runs(tmp_path / "runs")
    done = report_cli("--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "out"), "--only", "fig18")
    assert done.returncode == 0, done.stderr
    figures = sorted(p.name for p in (tmp_path / "out" / "figures").iterdir())
    assert figures == ["fig18.csv", "fig18.pdf", "fig18.png"]
    assert "not rendered yet" in (tmp_path / "out" / "README.md").read_text()


@pytest.mark.parametrize(("args", "message"), [(["--only", "fig99"], "unknown id(s) fig99"),
                                               (["--out", "{runs}/x"], "lies inside --runs"),
                                               (["--runs", "{runs}/nope"], "no such directory"),
                                               (["--records-only", "--records", "{runs}/nope"],
                                                "--records-only: no records at"),
                                               (["--records", "{runs}/nope"], "nope: no such directory")])
def test_cli_refuses_bad_input_before_writing(tmp_path: Path, args: list[str], message: str,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    runs = tmp_path / "runs"
    runs.mkdir()
    args = [a.format(runs=runs) for a in args]
    defaults = [] if "--runs" in args else ["--runs", str(runs)]
    defaults += [] if "--out" in args else ["--out", str(tmp_path / "out")]
    assert report_main([*defaults, *args, "--no-progress"]) == 2  # in-process: the same code path, no import cost
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and list(runs.iterdir()) == []


@pytest.mark.slow
def test_reproduce_runs_the_collector_after_the_presets(tmp_path: Path) -> None:
    from plls_bench.reproduce import main as reproduce_main

    runs, out = tmp_path / "runs", tmp_path / "out"
    assert reproduce_main(["--profile", "smoke", "--only", "mountaincar_data", "--runs", str(runs),
                           "--out", str(out)]) == 0
    assert (runs / "mountaincar_data" / "default" / "seed=0" / "status.json").is_file()
    readme = (out / "README.md").read_text()
    assert "Budget profile: **smoke**" in readme and "mountaincar_ppo/default: no runs" in readme


def test_a_broken_paper_csv_is_refused_naming_the_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    paper = tmp_path / "paper"
    paper.mkdir()
    for path in PAPER_DIR.glob("*.csv"):
        (paper / path.name).write_text(path.read_text())
    claims = (paper / "claims.csv").read_text().splitlines()
    claims[1] = claims[1].replace("repr_mse", "repr_mse_typo")
    (paper / "claims.csv").write_text("\n".join(claims))
    (tmp_path / "runs").mkdir()
    args = ["--runs", str(tmp_path / "runs"), "--out", str(tmp_path / "out"), "--paper", str(paper)]
    assert report_main(args) == 2
    assert "claims.csv line 2: unknown kind 'repr_mse_typo'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
    line = next(i for i, text in enumerate(claims) if ",final:stochastic," in text)  # a misspelt policy
    claims[1] = claims[1].replace("repr_mse_typo", "repr_mse")
    claims[line] = claims[line].replace(",final:stochastic,", ",final:stochastc,")
    (paper / "claims.csv").write_text("\n".join(claims))
    assert report_main(args) == 2
    assert f"claims.csv line {line + 1}: unknown param 'final:stochastc'" in capsys.readouterr().err
    claims[line] = claims[line].replace(",final:stochastc,", ",final:stochastic,")
    line = next(i for i, text in enumerate(claims) if ",Suite PPO beats the random policy" in text)  # fig18's check
    claims[line] = claims[line].replace(",Suite PPO beats the random policy", ",Suite PPO beats the randon policy")
    (paper / "claims.csv").write_text("\n".join(claims))
    assert report_main(args) == 2
    assert f"claims.csv line {line + 1}: unknown requires 'Suite PPO beats the randon policy" in capsys.readouterr().err
