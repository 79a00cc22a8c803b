"""docs/benchmarks.md sections: every bench script assembles and replaces its section the same way."""
from __future__ import annotations

from pathlib import Path

import pytest

from bench import benchmarks_md
from bench.benchmarks_md import announce, finish_section


def test_a_section_is_assembled_and_replaced_in_place(tmp_path: Path) -> None:
    path = tmp_path / "benchmarks.md"
    path.write_text("# Benchmarks\n\nhand-written text\n")
    args = ("speed", "Speed (toy bench)", "nice -n 10 python toy_bench", "How it was measured.",
            ["setting", "steps/s"])
    first = finish_section(*args, ["| a | **1** |"], notes=["A note."], path=path)
    assert first.splitlines()[:3] == ["## Speed (toy bench)", "", "Command: `nice -n 10 python toy_bench`  "]
    assert "| setting | steps/s |\n|---|---|\n| a | **1** |\n\nA note." in first
    assert "cores, load average" in first.splitlines()[3]
    finish_section(*args, ["| b | **2** |"], path=path)
    text = path.read_text()
    assert text.count("<!-- speed:begin -->") == 1 and "| b | **2** |" in text and "| a |" not in text
    assert text.startswith("# Benchmarks\n\nhand-written text\n")


def test_no_write_leaves_the_file_alone(tmp_path: Path) -> None:
    path = tmp_path / "benchmarks.md"
    finish_section("s", "T", "cmd", "m", ["h"], ["| 1 |"], write=False, path=path)
    assert not path.exists()


@pytest.mark.parametrize("niceness, prefix", [(0, ".venv/bin/python"), (7, "nice -n 7 .venv/bin/python")])
def test_the_command_names_the_priority_it_ran_at(monkeypatch: pytest.MonkeyPatch, niceness: int,
                                                  prefix: str) -> None:
    monkeypatch.setattr(benchmarks_md.os, "nice", lambda increment: niceness)
    assert announce("ppo_layouts.py", ["--iterations", "2"]) == f"{prefix} bench/ppo_layouts.py --iterations 2"
