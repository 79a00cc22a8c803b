"""Shared by the bench scripts: a one-line machine description and section-wise BENCHMARKS.md."""
from __future__ import annotations

import os
import platform
import shlex
import sys
from pathlib import Path

import torch

REPO = Path(__file__).resolve().parent.parent


def machine() -> str:
    """Host, CPU, cores, load average (timings on a shared machine need it) and torch version."""
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    cpu = platform.processor() or platform.machine()
    return f"{platform.node()}: {cpu}, {os.cpu_count()} cores, load average {load}; torch {torch.__version__}"


def announce(script: str, argv: list[str] | None) -> str:
    """Print and return the command line that reproduces this benchmark, and the machine before it."""
    command = f"nice -n 10 .venv/bin/python bench/{script} " + shlex.join(sys.argv[1:] if argv is None else argv)
    print(f"command: {command}\nmachine (before): {machine()}", flush=True)
    return command


def write_section(section: str, text: str, path: Path = REPO / "BENCHMARKS.md") -> None:
    """Replace (or append) the block between ``<!-- section:begin -->`` and ``<!-- section:end -->``."""
    begin, end = f"<!-- {section}:begin -->", f"<!-- {section}:end -->"
    old = path.read_text() if path.exists() else "# Benchmarks\n\nEach section is rewritten by the script it names.\n"
    block = f"{begin}\n{text.rstrip()}\n{end}"
    if begin in old and end in old:
        new = old[:old.index(begin)] + block + old[old.index(end) + len(end):]
    else:
        new = old.rstrip() + "\n\n" + block + "\n"
    path.write_text(new if new.endswith("\n") else new + "\n")
