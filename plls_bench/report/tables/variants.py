"""The variants view: ``tables/variants.{md,tex,csv}`` (one row per variant found, beside its
base: the preset's default, or the run it overrides), ``figures/variants_<preset>.*`` and one index
line per variant in the README."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from plls_bench.report.evidence.claim_settings import ClaimSettings, load_settings
from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import DEFAULT_VARIANT, Runs
from plls_bench.report.evidence.table_formats import NA, Table, fmt, plural
from plls_bench.report.evidence.variant_arms import Judged, Variant, found_variants, judge_preset, load_variant
from plls_bench.report.figures.variants import figure_name, variants_figure


def caption(settings: ClaimSettings) -> str:
    """The table's caption, with the protocol's settings it was judged at."""
    return (
        "Every variant dir found under the runs or the records (an ablation override, `reproduce --override "
        "KEY=VALUE`, or a declared sweep's value) beside its base: the run it overrides, which is the preset's "
        "default, or for a variant launched with `--precision` the preset's runs at that precision alone "
        "(plls_bench/report/evidence/variant_arms.py). Both arms' finished trials are read on the evaluations "
        "every one of them reaches, in env steps (an override may change the env steps of an iteration): "
        f"final = mean return over the last {settings.final_tail} of them (results/paper/claims.yaml, "
        "final_tail, as in the claims rows), curve = mean return over them; mean ± sample standard deviation "
        "over trials. The final returns are tested under the suite's declared verdict protocol "
        f"(plls_bench/report/evidence/protocol.py: two-sided p, alpha = {settings.alpha:g}, no test below "
        f"{settings.min_n} trials per arm), only where both arms ran at one budget, otherwise the row says what "
        "is missing; the tested variants of one preset are one Holm family, each decided at its Holm-adjusted "
        "p. The single last evaluation is a sensitivity reading, on its own p. Trials: variant + base. These "
        "comparisons are exploratory: a variant declares no planned n, so each regeneration at a new count is "
        "another look, and only the claims table's rows (judged once, at their planned n) are verdicts "
        "(docs/verdicts.md, One look per row).")


def columns(settings: ClaimSettings) -> list[str]:
    final = f"Final (mean of the last {settings.final_tail} evaluations)"
    return ["Preset", "Override", "Base", "Budget", "Trials", f"{final}: variant", f"{final}: base",
            "Curve mean: variant", "Curve mean: base", "Compared", "Variant vs base (final return)"]


def spread(values: np.ndarray) -> str:
    """``mean ± sd`` of per-trial scores ``(n,)``; the value alone for one trial; — for none."""
    if not len(values):
        return NA
    if len(values) == 1:
        return fmt(float(values[0]))
    return f"{fmt(float(values.mean()))} ± {fmt(float(values.std(ddof=1)))}"


def _budget(variant: Variant) -> str:
    own, base = variant.exp.budget or NA, variant.base.budget or NA
    return own if own == base else f"{own} (base: {base})"


def _row(variant: Variant, judged: Judged) -> tuple[list[str], dict]:
    counts = [len(f) for f in judged.final]
    cells = [variant.preset, variant.name, judged.base, _budget(variant), " + ".join(map(str, counts)),
             *map(spread, (*judged.final, *judged.curve)), judged.at, judged.verdict]
    record = {"preset": variant.preset, "variant": variant.name, "base": judged.base, "budget": variant.exp.budget,
              "base_budget": variant.base.budget, "n_variant": counts[0], "n_base": counts[1]}
    for name, pair in (("final", judged.final), ("curve", judged.curve), ("last", judged.last)):
        for arm, values in zip(("variant", "base"), pair):
            record[f"{name}_{arm}_mean"] = float(values.mean()) if len(values) else math.nan
            record[f"{name}_{arm}_std"] = float(values.std(ddof=1)) if len(values) > 1 else math.nan
    record.update({"compared": judged.at, "outcome": judged.outcome, **judged.test, "verdict": judged.verdict})
    return cells, record


def index_line(variant: Variant, judged: Judged) -> str:
    """The README's line for a variant: override, trials, budget, where its runs are, its base, the verdict."""
    dirs = sorted({str(Path(t.path).parent) for t in variant.exp.trials})
    where = ", ".join(f"`{d}`" for d in dirs) or "no readable run dir"
    base = (f"{plural(len(variant.base.trials), 'trial')}, budget {variant.base.budget}"
            if variant.base.trials else "no runs")
    word = "default" if judged.base == DEFAULT_VARIANT else f"base `{judged.base}`"
    return (f"`{variant.preset}` `{variant.name}`: {plural(len(variant.exp.trials), 'trial')}, budget "
            f"{variant.exp.budget or NA}, runs in {where}; {word}: {base}; vs {word.split(' ')[0]}: {judged.verdict}")


def variants_view(runs: Runs, entry: Entry, opts: Options) -> Output:
    """The table, one figure per preset with variants (where returns are logged) and the index lines."""
    rows, records, lines, trials, figures = [], [], [], {}, {}
    settings = load_settings(opts.paper_dir, None)  # the protocol block; the claims table checks the names
    for preset, names in found_variants(runs).items():
        variants = [load_variant(runs, preset, name) for name in names]
        for variant, judged in zip(variants, judge_preset(runs, variants, settings)):
            cells, record = _row(variant, judged)
            rows.append(cells)
            records.append(record)
            lines.append(index_line(variant, judged))
            trials[f"{preset} {variant.name}"] = len(variant.exp.trials)
        drawn = variants_figure(preset, variants, settings.final_tail)
        if drawn is not None:
            figures[figure_name(preset)] = drawn
    table = Table(f"{entry.ref}. {entry.title}", caption(settings), columns(settings), rows,
                  pd.DataFrame(records) if records else None)
    if not rows:  # a complete answer, not a gap: the view needs no run of its own
        table.notes.append("No variant found: every run dir is a preset's default.")
    return Output(table=table, trials=trials, figures=figures, lines=lines)
