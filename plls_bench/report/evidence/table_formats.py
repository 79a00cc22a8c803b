"""Tables rendered three ways (Markdown, LaTeX, CSV) and the number formats they share, plus the
paper's own numbers (``results/paper/*.csv``)."""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

NA = "—"  # a cell the suite has no number for
_TEX_ESCAPES = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\^{}",
                "±": r"$\pm$", "≠": r"$\neq$", "≤": r"$\leq$", "≥": r"$\geq$", "×": r"$\times$",
                "—": "--", "–": "--", ">": r"$>$", "<": r"$<$"}


@dataclass
class Table:
    """``rows`` hold display strings; ``data`` the same content as raw values for the CSV."""

    title: str
    caption: str
    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    data: pd.DataFrame | None = None
    notes: list[str] = field(default_factory=list)

    def markdown(self) -> str:
        def cell(text: str) -> str:
            return str(text).replace("|", "\\|").replace("\n", " ")

        lines = [f"**{self.title}.** {self.caption}", "",
                 "| " + " | ".join(map(cell, self.columns)) + " |",
                 "|" + "|".join("---" for _ in self.columns) + "|"]
        lines += ["| " + " | ".join(map(cell, row)) + " |" for row in self.rows]
        lines += [""] + [f"- {note}" for note in self.notes] if self.notes else []
        return "\n".join(lines) + "\n"

    def latex(self, label: str) -> str:
        spec = "|" + "|".join("l" if i == 0 else "c" for i in range(len(self.columns))) + "|"
        body = [" & ".join(tex(c) for c in row) + r" \\ \hline" for row in self.rows]
        notes = [r"\par\footnotesize " + tex(note) for note in self.notes]
        return "\n".join([
            r"\begin{table}[h]", r"\centering", rf"\caption{{{tex(self.title)}. {tex(self.caption)}}}",
            rf"\label{{tab:{label}}}", r"\small", rf"\begin{{tabular}}{{{spec}}}", r"\hline",
            " & ".join(tex(c) for c in self.columns) + r" \\ \hline", *body, r"\end{tabular}",
            *notes, r"\end{table}"]) + "\n"

    def csv(self) -> str:
        if self.data is not None:
            return self.data.to_csv(index=False, lineterminator="\n")
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerows([self.columns, *self.rows])
        return buffer.getvalue()


def tex(text: object) -> str:
    """``text`` with LaTeX's special characters escaped."""
    return "".join(_TEX_ESCAPES.get(ch, ch) for ch in str(text))


# --------------------------------------------------------------------------- numbers
def fmt(value: object, digits: int = 4) -> str:
    """A compact number: integers with thousands separators, small floats in short scientific
    notation (4e-04 -> 4e-4, as the paper writes them), others to ``digits`` significant figures."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return NA
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, float) and math.isinf(value):
        return "∞" if value > 0 else "-∞"
    if float(value).is_integer() and abs(value) >= 1:
        return f"{int(value):,}"
    if value != 0 and abs(value) < 1e-2:
        mantissa, exponent = f"{value:.{digits - 1}e}".split("e")
        mantissa = mantissa.rstrip("0").rstrip(".")
        return f"{mantissa}e{int(exponent)}"
    return f"{value:.{digits}g}"


def plural(n: int, word: str) -> str:
    """``1 run``, ``3 runs``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def fmt_ci(value: float, interval: tuple[float, float], digits: int = 4) -> str:
    """``value [low, high]``, or just the value when there is no interval (one trial)."""
    if any(math.isnan(v) for v in interval):
        return fmt(value, digits)
    return f"{fmt(value, digits)} [{fmt(interval[0], digits)}, {fmt(interval[1], digits)}]"


# --------------------------------------------------------------------------- paper numbers
HYPER_COLUMNS = ("hyperparameter", "key", "paper_value", "paper_baseline", "source")
PAPER_COLUMNS = {
    "table1": HYPER_COLUMNS, "table2": HYPER_COLUMNS,
    "table3": ("model", "experiment", "total_parameters", "trainable_parameters", "iterations_to_convergence",
               "sampled_frequency", "source"),
    "claims": ("claim", "entry", "kind", "experiment", "baseline", "requires", "param", "paper", "paper_value",
               "paper_pm", "rule", "threshold", "threshold_high", "x_axis", "from_x", "needs_x", "min_budget",
               "source"),
}


def read_paper(paper_dir: Path, name: str) -> list[dict[str, str]]:
    """Rows of ``<paper_dir>/<name>.csv`` (one of :data:`PAPER_COLUMNS`), each citing its source;
    ValueError naming the file and line for a missing column or citation."""
    path = paper_dir / f"{name}.csv"
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        missing = [c for c in PAPER_COLUMNS[name] if c not in (reader.fieldnames or [])]
        rows = list(reader)
    if missing:
        raise ValueError(f"{path}: missing column(s) {', '.join(missing)}")
    uncited = [i for i, row in enumerate(rows, 2) if not (row.get("source") or "").strip()]
    if uncited:
        raise ValueError(f"{path}: line(s) {uncited} have no source citation")
    return rows
