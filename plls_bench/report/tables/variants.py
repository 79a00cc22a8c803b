"""The variants view: ``tables/variants.{md,tex,csv}`` (one row per variant found, beside its
preset's default), ``figures/variants_<preset>.*`` and one index line per variant in the README."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.protocol import ALPHA, MIN_N
from plls_bench.report.evidence.table_formats import NA, Table, fmt, plural
from plls_bench.report.evidence.variant_arms import Judged, Variant, found_variants, judge, load_variant
from plls_bench.report.figures.variants import figure_name, variants_figure

CAPTION = (
    "Every variant dir found under the runs or the records (an ablation override, `reproduce --override "
    "KEY=VALUE`, or a declared sweep's value) beside its preset's default runs. Both arms' finished trials are "
    "read on the evaluations every one of them reaches, in env steps (an override may change the env steps of "
    "an iteration): final = mean return at the last of them, curve = mean "
    "return over them; mean ± sample standard deviation over trials. The final returns are tested under the "
    f"suite's declared verdict protocol (plls_bench/report/evidence/protocol.py: two-sided p, alpha = {ALPHA}, no test "
    f"below {MIN_N} trials per arm), only where both arms ran at one budget; otherwise the row says what is "
    "missing. Trials: variant + default.")
COLUMNS = ["Preset", "Override", "Budget", "Trials", "Final return: variant", "Final return: default",
           "Curve mean: variant", "Curve mean: default", "Compared", "Variant vs default (final return)"]


def spread(values: np.ndarray) -> str:
    """``mean ± sd`` of per-trial scores ``(n,)``; the value alone for one trial; — for none."""
    if not len(values):
        return NA
    if len(values) == 1:
        return fmt(float(values[0]))
    return f"{fmt(float(values.mean()))} ± {fmt(float(values.std(ddof=1)))}"


def _budget(variant: Variant) -> str:
    own, base = variant.exp.budget or NA, variant.default.budget or NA
    return own if own == base else f"{own} (default: {base})"


def _row(variant: Variant, judged: Judged) -> tuple[list[str], dict]:
    counts = [len(f) for f in judged.final]
    cells = [variant.preset, variant.name, _budget(variant), " + ".join(map(str, counts)),
             *map(spread, (*judged.final, *judged.curve)), judged.at, judged.verdict]
    record = {"preset": variant.preset, "variant": variant.name, "budget": variant.exp.budget,
              "default_budget": variant.default.budget, "n_variant": counts[0], "n_default": counts[1]}
    for name, pair in (("final", judged.final), ("curve", judged.curve)):
        for arm, values in zip(("variant", "default"), pair):
            record[f"{name}_{arm}_mean"] = float(values.mean()) if len(values) else math.nan
            record[f"{name}_{arm}_std"] = float(values.std(ddof=1)) if len(values) > 1 else math.nan
    record.update({"compared": judged.at, "outcome": judged.outcome, **judged.test, "verdict": judged.verdict})
    return cells, record


def index_line(variant: Variant, judged: Judged) -> str:
    """The README's line for a variant: override, trials, budget, where its runs are, the verdict."""
    dirs = sorted({str(Path(t.path).parent) for t in variant.exp.trials})
    where = ", ".join(f"`{d}`" for d in dirs) or "no readable run dir"
    default = (f"{plural(len(variant.default.trials), 'trial')}, budget {variant.default.budget}"
               if variant.default.trials else "no runs")
    return (f"`{variant.preset}` `{variant.name}`: {plural(len(variant.exp.trials), 'trial')}, budget "
            f"{variant.exp.budget or NA}, runs in {where}; default: {default}; vs default: {judged.verdict}")


def variants_view(runs: Runs, entry: Entry, opts: Options) -> Output:
    """The table, one figure per preset with variants (where returns are logged) and the index lines."""
    rows, records, lines, trials, figures = [], [], [], {}, {}
    for preset, names in found_variants(runs).items():
        variants = [load_variant(runs, preset, name) for name in names]
        for variant in variants:
            judged = judge(runs, variant)
            cells, record = _row(variant, judged)
            rows.append(cells)
            records.append(record)
            lines.append(index_line(variant, judged))
            trials[f"{preset} {variant.name}"] = len(variant.exp.trials)
        drawn = variants_figure(preset, variants)
        if drawn is not None:
            figures[figure_name(preset)] = drawn
    table = Table(f"{entry.ref}. {entry.title}", CAPTION, COLUMNS, rows, pd.DataFrame(records) if records else None)
    if not rows:  # a complete answer, not a gap: the view needs no run of its own
        table.notes.append("No variant found: every run dir is a preset's default.")
    return Output(table=table, trials=trials, figures=figures, lines=lines)
