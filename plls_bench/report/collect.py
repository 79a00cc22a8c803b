"""Render registry ids from a runs dir into an output dir: figures (PNG, PDF and the tidy CSV of
what they draw), tables (Markdown, LaTeX, CSV), ``index.json`` (per-id status) and the
``README.md`` index. Reads the runs dir only; writes only under the output dir, atomically."""
from __future__ import annotations

import logging
import struct
import traceback
from collections.abc import Iterable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json, read_json
from plls_bench.core.progress_bars import progress_bar
from plls_bench.report.claims.claims_table import read_claims
from plls_bench.report.evidence.entry_types import Entry, IdStatus, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.returns import X_AXES
from plls_bench.report.evidence.table_formats import PAPER_COLUMNS, read_paper
from plls_bench.report.figures.plot import DPI, save_figure
from plls_bench.report.headline import write_front_page
from plls_bench.report.readme import write_readme
from plls_bench.report.registry import BY_ID, ENTRIES

log = logging.getLogger(__name__)
PAPER_DIR = Path(__file__).resolve().parents[2] / "results" / "paper"


class ReportError(ValueError):
    """Bad collector input (paths, ids, axis); raised before anything is read or written."""


def check_inputs(runs_dir: Path | None, out_dir: Path, only: Iterable[str] | None, x_axis: str, paper_dir: Path,
                 records_dir: Path | None = None) -> None:
    """One clear error for bad input, before any compute or write. ``runs_dir`` None: records only."""
    if runs_dir is None:
        if records_dir is None or not records_dir.is_dir():
            raise ReportError(f"--records-only: no records at {records_dir}")
    elif not runs_dir.is_dir() and not (records_dir is not None and records_dir.is_dir()):
        raise ReportError(f"--runs {runs_dir}: no such directory"
                          + (f" (and no records at {records_dir})" if records_dir is not None else ""))
    elif out_dir.resolve() == runs_dir.resolve() or runs_dir.resolve() in out_dir.resolve().parents:
        raise ReportError(f"--out {out_dir} lies inside --runs {runs_dir}: the collector never writes there")
    unknown = sorted(set(only or ()) - set(BY_ID))
    if unknown:
        raise ReportError(f"--only: unknown id(s) {', '.join(unknown)}; known: {', '.join(BY_ID)}")
    if x_axis not in X_AXES:
        raise ReportError(f"--x-axis {x_axis!r}: choose one of {', '.join(X_AXES)}")
    missing = [name for name in PAPER_COLUMNS if not (paper_dir / f"{name}.csv").is_file()]
    if missing:
        raise ReportError(f"--paper {paper_dir}: missing {', '.join(f'{m}.csv' for m in missing)}")
    try:
        for name in PAPER_COLUMNS:
            read_paper(paper_dir, name)
        read_claims(paper_dir)
    except ValueError as err:
        raise ReportError(f"--paper: {err}") from err


def write_output(entry: Entry, output: Output, out_dir: Path) -> list[str]:
    """Write what a build produced; returns the paths written, relative to ``out_dir``."""
    paths: list[Path] = []
    if output.figure is not None:
        paths += save_figure(output.figure, out_dir / "figures" / entry.id)
        if output.data is not None:
            path = out_dir / "figures" / f"{entry.id}.csv"
            atomic_write_bytes(path, output.data.to_csv(index=False, lineterminator="\n").encode())
            paths.append(path)
    for name, (figure, data) in output.figures.items():
        paths += save_figure(figure, out_dir / "figures" / name)
        path = out_dir / "figures" / f"{name}.csv"
        atomic_write_bytes(path, data.to_csv(index=False, lineterminator="\n").encode())
        paths.append(path)
    if output.table is not None:
        base = out_dir / "tables" / entry.id
        for ext, text in (("md", output.table.markdown()), ("tex", output.table.latex(entry.id)),
                          ("csv", output.table.csv())):
            atomic_write_bytes(base.with_suffix(f".{ext}"), text.encode())
            paths.append(base.with_suffix(f".{ext}"))
    return [str(p.relative_to(out_dir)) for p in paths]


def render_one(entry: Entry, runs_dir: Path | None, out_dir: Path, opts: Options,
               records_dir: Path | None = None) -> IdStatus:
    """Build and write one id; a failure is recorded in its status, never raised."""
    runs = Runs(runs_dir, records_dir)
    status = IdStatus(entry.id, entry.ref, entry.title, entry.kind, "error", list(entry.experiments), entry.reads)
    try:
        output = entry.build(runs, entry, opts)
        status.files = write_output(entry, output, out_dir)
    except Exception as err:  # one broken id must not stop the others; the status names it
        log.error("%s failed:\n%s", entry.id, traceback.format_exc())
        status.error = f"{type(err).__name__}: {err}"
    else:
        status.trials, status.lines = output.trials, output.lines
        status.status = "empty" if output.empty else "partial" if runs.gaps else "ok"
    status.gaps = [str(gap) for gap in runs.gaps]
    return status


def render_all(runs_dir: str | Path | None, out_dir: str | Path, only: Iterable[str] | None = None,
               x_axis: str = "iteration", paper_dir: str | Path = PAPER_DIR,
               progress: bool = False, command: str = "",
               records_dir: str | Path | None = None) -> dict[str, IdStatus]:
    """Render every registry id (or ``only`` those) from the runs and, when given, the committed
    records, and regenerate ``index.json`` and ``README.md``; returns the status of each id
    rendered. ``runs_dir`` None reads the records alone, as a fresh clone has them. The
    integration test's entry point."""
    runs_dir = None if runs_dir is None else Path(runs_dir)
    out_dir, paper_dir = Path(out_dir), Path(paper_dir)
    records = None if records_dir is None else Path(records_dir)
    only = list(only) if only else None
    check_inputs(runs_dir, out_dir, only, x_axis, paper_dir, records)
    opts = Options(x_axis, paper_dir)
    entries = [BY_ID[i] for i in only] if only else list(ENTRIES)
    bar = progress_bar(entries, disable=not progress, desc="report")
    rendered = {entry.id: render_one(entry, runs_dir, out_dir, opts, records) for entry in bar}
    index = _merge_index(out_dir / "index.json", rendered)
    meta = {"runs": None if runs_dir is None else str(runs_dir), "records": None if records is None else str(records),
            "x_axis": x_axis, "command": command}
    atomic_write_json(out_dir / "index.json", {"meta": meta, "ids": [asdict(s) for s in index]})
    write_readme(out_dir, runs_dir, index, meta)
    write_front_page(out_dir)  # the repository README's headline, when out_dir is this checkout's results/
    return rendered


def _merge_index(path: Path, rendered: dict[str, IdStatus]) -> list[IdStatus]:
    """Registry order; ids not rendered now keep their previous status (``--only``)."""
    previous = {}
    old = read_json(path)
    for item in (old or {}).get("ids", []) if isinstance(old, dict) else []:
        try:
            previous[item["id"]] = IdStatus(**item)
        except (TypeError, KeyError):
            continue
    return [rendered.get(e.id) or previous.get(e.id) or
            IdStatus(e.id, e.ref, e.title, e.kind, "empty", list(e.experiments), e.reads,
                     gaps=["not rendered yet: run the collector without --only"]) for e in ENTRIES]


def png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's header."""
    header = path.read_bytes()[:24]
    if header[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path} is not a PNG")
    return struct.unpack(">II", header[16:24])


def verify_outputs(out_dir: str | Path, statuses: dict[str, IdStatus]) -> list[str]:
    """What is wrong with the files ``render_all`` wrote (an empty list when nothing is): every
    figure a non-blank PNG of its registry size (inches x DPI) with its PDF and data CSV, every
    table in Markdown, LaTeX and CSV. For tests over synthetic and smoke-profile runs."""
    from matplotlib.image import imread

    out_dir, problems = Path(out_dir), []
    for id_, status in statuses.items():
        entry = BY_ID[id_]
        if status.status == "error":
            problems.append(f"{id_}: {status.error}")
            continue
        if entry.kind == "table":
            paths = [out_dir / "tables" / f"{id_}.{ext}" for ext in ("md", "tex", "csv")]
            problems += [f"{id_}: {p.name} missing or empty" for p in paths
                         if not p.is_file() or not p.stat().st_size]
            problems += [f"{id_}: {name} missing or blank" for name in status.files if name.endswith(".png")
                         and (not (out_dir / name).is_file() or float(np.ptp(imread(out_dir / name)[..., :3])) == 0)]
            continue
        png, want = out_dir / "figures" / f"{id_}.png", (round(entry.size[0] * DPI), round(entry.size[1] * DPI))
        if not png.is_file() or png_size(png) != want:
            problems.append(f"{id_}: {png.name} missing or not {want[0]}x{want[1]} pixels")
        elif float(np.ptp(imread(png)[..., :3])) == 0:
            problems.append(f"{id_}: {png.name} is blank")
        pdf = out_dir / "figures" / f"{id_}.pdf"
        if not pdf.is_file() or pdf.read_bytes()[:4] != b"%PDF":
            problems.append(f"{id_}: {pdf.name} missing or not a PDF")
        if status.status != "empty" and not (out_dir / "figures" / f"{id_}.csv").is_file():
            problems.append(f"{id_}: {id_}.csv (the plotted data) missing")
    return problems
