"""Shared by the bench scripts: a one-line machine description and section-wise docs/benchmarks.md."""
from __future__ import annotations

import os
import platform
import shlex
import sys
from pathlib import Path

import torch

from plls_bench.core.atomic_files import atomic_write_bytes
from plls_bench.rundirs.devices import cpu_model

REPO = Path(__file__).resolve().parent.parent


def machine() -> str:
    """Host, CPU model, cores, load average (timings on a shared machine need it) and torch version."""
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return (f"{platform.node()}: {platform.machine()}, {cpu_model()}, {os.cpu_count()} cores, "
            f"load average {load}; torch {torch.__version__}")


def announce(script: str, argv: list[str] | None) -> str:
    """Print and return the command line that reproduces this benchmark, and the machine before it."""
    niceness = os.nice(0)  # the priority it really ran at: timings beside other load depend on it
    prefix = f"nice -n {niceness} " if niceness else ""
    command = f"{prefix}.venv/bin/python bench/{script} " + shlex.join(sys.argv[1:] if argv is None else argv)
    print(f"command: {command}\nmachine (before): {machine()}", flush=True)
    return command


def write_section(section: str, text: str, path: Path = REPO / "docs" / "benchmarks.md") -> None:
    """Replace (or append) the block between ``<!-- section:begin -->`` and ``<!-- section:end -->``."""
    begin, end = f"<!-- {section}:begin -->", f"<!-- {section}:end -->"
    old = path.read_text() if path.exists() else "# Benchmarks\n\nEach section is rewritten by the script it names.\n"
    block = f"{begin}\n{text.rstrip()}\n{end}"
    if begin in old and end in old:
        new = old[:old.index(begin)] + block + old[old.index(end) + len(end):]
    else:
        new = old.rstrip() + "\n\n" + block + "\n"
    atomic_write_bytes(path, (new if new.endswith("\n") else new + "\n").encode())


def finish_section(section: str, title: str, command: str, method: str, header: list[str],
                   rows: list[str], notes: list[str] | None = None, write: bool = True,
                   path: Path = REPO / "docs" / "benchmarks.md") -> str:
    """Print the machine after the run, assemble a section and write it unless ``write`` is false.

    ``header`` holds the column names; the text is: title, command, machine, the ``method``
    paragraph, the table, then ``notes`` (lines after a blank line). Returns the text.
    """
    after = machine()
    print(f"machine (after): {after}", flush=True)
    table = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header), *rows]
    text = "\n".join([f"## {title}", "", f"Command: `{command}`  ", f"Machine (after): {after}  ",
                      method, "", *table, *(["", *notes] if notes else [])])
    if write:
        write_section(section, text, path)
    return text
