"""``figures/variants_<preset>``: the preset's default return curve beside each of its variants'
(mean over trials, +- one standard deviation shaded, as the paper's curves) against env steps, trial
counts and each arm's final return (the protocol's: mean of the last ``final_tail`` evaluations) in
the legend. Each variant's base is drawn where it is the default or a variant of its own."""
from __future__ import annotations

import pandas as pd
from matplotlib.figure import Figure

from plls_bench.report.evidence.load import DEFAULT_VARIANT
from plls_bench.report.evidence.protocol import tail_mean
from plls_bench.report.evidence.returns import Curves, x_label
from plls_bench.report.evidence.table_formats import fmt
from plls_bench.report.evidence.variant_arms import X_AXIS, Variant, matched_or_none
from plls_bench.report.figures.curves import band_frame, draw_band
from plls_bench.report.figures.plot import new_figure, suptitle

SIZE = (8.0, 5.0)  # inches: one axis, a legend of up to a handful of variants
DEFAULT_COLOUR = "black"
VARIANT_COLOURS = ("#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf")


def figure_name(preset: str) -> str:
    return f"variants_{preset}"


def legend(name: str, curves: Curves, tail: int) -> str:
    """``name (n trials, budget b; final x, mean of the last k evaluations)``: the final return over
    the arm's finished trials on the evaluations all of them reach, as the variants table reads it."""
    arm = matched_or_none(curves)
    final = "" if arm is None else (f"; final {fmt(float(tail_mean(arm.values[0], tail).mean()))} (mean of the "
                                    f"last {min(tail, len(arm.grid))} evaluations)")
    return f"{name} ({curves.n} trial{'' if curves.n == 1 else 's'}, budget {curves.experiment.budget}{final})"


def variants_figure(preset: str, variants: list[Variant], tail: int) -> tuple[Figure, pd.DataFrame] | None:
    """The figure of ``preset``'s variants and its tidy data, final returns over the last ``tail``
    evaluations in the legend; None when no arm has a return curve."""
    drawn = [v for v in variants if v.curves is not None and v.curves.n]
    default = next((v.base_curves for v in variants if v.base_curves is not None
                    and v.base.variant == DEFAULT_VARIANT), None)
    arms: list[tuple[str, Curves, str]] = [(v.name, v.curves, VARIANT_COLOURS[i % len(VARIANT_COLOURS)])
                                           for i, v in enumerate(drawn)]
    if default is not None and default.n:  # drawn last, so a variant that matches it does not hide it
        arms.append((DEFAULT_VARIANT, default, DEFAULT_COLOUR))
    if not arms:
        return None
    fig = new_figure(SIZE)
    ax = fig.add_subplot()
    frames, trials = [], {}
    for name, curves, colour in arms:
        frame = band_frame(name, preset, X_AXIS, curves.grid, curves.values)
        frame.insert(1, "budget", curves.experiment.budget)
        draw_band(ax, frame, colour, legend(name, curves, tail))
        frames.append(frame)
        trials[name] = curves.n
    ax.set_xlabel(x_label(arms[0][1].experiment, X_AXIS))
    ax.set_ylabel("average return")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=7)
    suptitle(fig, "Variants", f"{preset}: the default beside each variant found", trials)
    return fig, pd.concat(frames, ignore_index=True)
