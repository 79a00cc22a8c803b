"""The types every part of the collector shares: a registry entry, its sources, the options a
build receives, what a build returns, and the status of a rendered id (index.json, the README)."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

    from plls_bench.report.evidence.load import Runs
    from plls_bench.report.evidence.table_formats import Table

PLLS_RED, BASE_BLUE, VS_GREEN = "#d62728", "#1f77b4", "#2ca02c"  # the paper's Fig. 20 colours


@dataclass(frozen=True)
class Source:
    """An experiment preset (variant ``default``) feeding an entry, and how it is labelled."""

    experiment: str
    label: str
    color: str = PLLS_RED


@dataclass(frozen=True)
class Options:
    x_axis: str
    paper_dir: Path


@dataclass
class Output:
    """What a build produced. ``data`` is the tidy (long) table of what was drawn; ``trials``
    maps each series to the number of trials (or runs) it shows."""

    figure: Figure | None = None
    data: pd.DataFrame | None = None
    table: Table | None = None
    trials: dict[str, int] = field(default_factory=dict)
    empty: bool = False
    # figures beyond the entry's own, by file name (``variants_<preset>``): each with its tidy data
    figures: dict[str, tuple[Figure, pd.DataFrame]] = field(default_factory=dict)
    lines: list[str] = field(default_factory=list)  # the README's index lines of what the build found


Build = Callable[["Runs", "Entry", Options], Output]


@dataclass(frozen=True)
class Entry:
    """One table or figure of the paper (or one the suite adds): where it comes from, how it is
    drawn. ``size`` is the figure size in inches (pixels = inches x DPI)."""

    id: str
    ref: str
    title: str
    sources: tuple[Source, ...]
    build: Build
    reads: str
    kind: str = "figure"
    size: tuple[float, float] = (7.0, 4.5)
    references: tuple[str, ...] = ()  # presets read for a reference, not drawn as a source (random policy)

    @property
    def experiments(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys([*(s.experiment for s in self.sources), *self.references]))


@dataclass
class IdStatus:
    """What rendering one registry id gave: a row of ``index.json`` and a section of the README."""

    id: str
    ref: str
    title: str
    kind: str
    status: str
    experiments: list[str]
    reads: str
    files: list[str] = field(default_factory=list)  # relative to the output dir
    trials: dict[str, int] = field(default_factory=dict)
    gaps: list[str] = field(default_factory=list)
    error: str | None = None
    lines: list[str] = field(default_factory=list)  # index lines (Output.lines): one per variant found
