"""Figure plumbing: figures are built with matplotlib's object API on the Agg canvas chosen here
(never pyplot, so no global backend state), titled with the paper's figure number and the
number of trials, and saved atomically as PNG and PDF."""
from __future__ import annotations

import io
import textwrap
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from plls_bench.core.atomic_files import atomic_write_bytes
from plls_bench.report.evidence.entry_types import Entry, Output
from plls_bench.report.evidence.table_formats import plural

if TYPE_CHECKING:
    from plls_bench.report.evidence.load import Runs

DPI = 100  # PNG pixels = figure inches x DPI (the registry's sizes)
PLLS_LIGHT, PURPLE_DARK, PURPLE_LIGHT = "#f4a6a6", "#4b0082", "#b39ddb"
BLUE_DARK, BLUE_LIGHT = "#1f3b99", "#90b4f0"


def new_figure(size: tuple[float, float]) -> Figure:
    fig = Figure(figsize=size, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, base: Path) -> list[Path]:
    """Write ``base.png`` and ``base.pdf`` (each via a temp file and rename)."""
    paths = []
    for ext in ("png", "pdf"):
        buffer = io.BytesIO()
        # no creation date in the PDF: regenerating unchanged results gives unchanged files
        fig.savefig(buffer, format=ext, dpi=DPI, metadata={"CreationDate": None} if ext == "pdf" else None)
        path = base.with_suffix(f".{ext}")
        atomic_write_bytes(path, buffer.getvalue())
        paths.append(path)
    return paths


def trials_text(trials: dict[str, int], unit: str = "trial") -> str:
    """``PL-LS + PPO: 7 trials, PPO: 6 trials`` (the count each series shows)."""
    return ", ".join(f"{label}: {plural(n, unit)}" for label, n in trials.items())


# Characters of a 10-point title per inch of figure width: a longer line is wrapped, not clipped.
TITLE_CHARS_PER_INCH = 13


def _title(fig: Figure, text: str) -> None:
    width = max(20, int(fig.get_figwidth() * TITLE_CHARS_PER_INCH))
    fig.suptitle("\n".join(textwrap.fill(line, width) for line in text.split("\n")), fontsize=10)


def suptitle(fig: Figure, ref: str, title: str, trials: dict[str, int], unit: str = "trial") -> None:
    _title(fig, f"{ref} (suite): {title}\n{trials_text(trials, unit)}")


def placeholder(size: tuple[float, float], ref: str, title: str, problems: list[str]) -> Figure:
    """A figure saying there is nothing to draw and why (it keeps the index complete)."""
    fig = new_figure(size)
    _title(fig, f"{ref} (suite): {title}\nno data: 0 trials")
    ax = fig.add_subplot()
    ax.set_axis_off()
    lines = [textwrap.shorten(p, 110) for p in problems[:8]] + (["..."] if len(problems) > 8 else [])
    ax.text(0.5, 0.5, "\n".join(lines) or "no runs", ha="center", va="center", fontsize=8, wrap=True)
    return fig


def empty_output(runs: Runs, entry: Entry, title: str) -> Output:
    """The build result when an entry has nothing to draw: a placeholder listing the gaps."""
    return Output(placeholder(entry.size, entry.ref, title, [str(g) for g in runs.gaps]),
                  trials={s.label: 0 for s in entry.sources}, empty=True)


def rgb_colours(points: np.ndarray) -> np.ndarray:
    """Points ``(N, 3)`` coloured RGB = each coordinate min-max normalised to [0, 1] (Figs 7, 8)."""
    low, high = points.min(axis=0), points.max(axis=0)
    return np.clip((points - low) / np.where(high > low, high - low, 1.0), 0.0, 1.0)


def letter(i: int) -> str:
    """Sub-figure letters as the paper uses them: (a), (b), ..., (z), (aa), ..."""
    text = ""
    i += 1
    while i:
        i, rem = divmod(i - 1, 26)
        text = chr(97 + rem) + text
    return f"({text})"
