"""Curve figures: average return over trials (Figs 10, 18, 20, 21) and representation training
losses, train vs validation (Figs 6, 13, 15). Mean line, +- one standard deviation shaded, as in
the paper; the tidy data beside each figure also carry the 95% bootstrap CI of the mean."""
from __future__ import annotations

import numpy as np
import pandas as pd

from plls_bench.report.evidence.entry_types import BASE_BLUE, PLLS_RED, Entry, Options, Output, Source
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.matched import NotJudged, matched
from plls_bench.report.evidence.returns import Curves, load_curves, x_label
from plls_bench.report.evidence.stats import align, band
from plls_bench.report.evidence.table_formats import fmt, plural
from plls_bench.report.figures.plot import empty_output, new_figure, suptitle


def band_frame(series: str, experiment: str, x_name: str, grid: np.ndarray, values: np.ndarray) -> pd.DataFrame:
    """The tidy data of one curve band: per x of ``grid`` ``(P,)``, :func:`band` of ``values`` ``(n, P)``."""
    stats = band(values)
    return pd.DataFrame({"series": series, "experiment": experiment, "x_axis": x_name, "x": grid, **stats})


def draw_band(ax, frame: pd.DataFrame, color: str, label: str) -> None:
    """The mean line of :func:`band_frame`'s data, +- one standard deviation shaded."""
    ax.plot(frame["x"], frame["mean"], color=color, lw=1.6, label=label)
    ax.fill_between(frame["x"], frame["mean"] - frame["std"], frame["mean"] + frame["std"],
                    color=color, alpha=0.2, lw=0)


def _budgets(runs: Runs, entry: Entry) -> str:
    names = sorted({b for s in entry.sources if (b := runs.experiment(s.experiment).budget)})
    return f"budget {'/'.join(names)}" if names else "no runs"


def return_curves(runs: Runs, entry: Entry, opts: Options, *, sampled: bool = False) -> Output:
    """Mean return over trials against ``opts.x_axis``, one series per source; a dashed line where
    the sources are compared (the last evaluation every finished trial of each reaches) when some
    curve goes further, and the random policy's mean episode return read from the data preset in
    ``entry.references`` (``metrics/dataset.json``: the episodes its random-policy dataset came from).
    ``sampled`` adds each source's mean return on the same test episodes with sampled actions, a
    thin dashed line (docs/decisions.md#d20: the paper does not say which its curves show)."""
    methods = [(s, load_curves(runs, runs.experiment(s.experiment), s.label, opts.x_axis)) for s in entry.sources]
    trials = {s.label: c.n for s, c in methods}
    title = f"{entry.title} ({_budgets(runs, entry)})"
    if not any(c.n for _, c in methods):
        return empty_output(runs, entry, title)
    fig = new_figure(entry.size)
    ax = fig.add_subplot()
    frames = []
    for source, curves in methods:
        if curves.n:
            frame = band_frame(source.label, source.experiment, opts.x_axis, curves.grid, curves.values)
            early = int((~curves.complete_seeds()).sum())
            note = f", {early} stop early" if early else ""
            draw_band(ax, frame, source.color, f"{source.label} ({curves.n}{note})")
            frames.append(frame)
            if sampled:
                frames += _draw_sampled(ax, runs, source, opts.x_axis)
    if opts.x_axis != "wall_s":  # wall time is interpolated per trial: no evaluation x is shared
        _mark_common_x(ax, [c for _, c in methods if c.n and c.finished_seeds().any()])
    for preset in entry.references:
        if (frame := _random_line(runs, preset, methods, opts.x_axis)) is None:
            continue
        ax.plot(frame["x"], frame["mean"], color="grey", lw=1.0, ls=":", label=frame["series"].iloc[0])
        frames.append(frame)
    first = next(c for _, c in methods if c.n)
    ax.set_xlabel(x_label(first.experiment, opts.x_axis))
    ax.set_ylabel("average return")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    suptitle(fig, entry.ref, title, trials)
    return Output(fig, pd.concat(frames, ignore_index=True), trials=trials)


def _draw_sampled(ax, runs: Runs, source: Source, x_axis: str) -> list[pd.DataFrame]:
    """The source's mean return with sampled actions, where its runner records one (PPO)."""
    exp = runs.experiment(source.experiment)
    if exp.cfg("algo.name") != "ppo":
        return []
    curves = load_curves(runs, exp, source.label, x_axis, policy="stochastic")
    if not curves.n:
        return []
    frame = band_frame(f"{source.label}, sampled actions", source.experiment, x_axis, curves.grid, curves.values)
    ax.plot(frame["x"], frame["mean"], color=source.color, lw=1.0, ls="--", label=f"{source.label}, sampled actions")
    return [frame]


def _mark_common_x(ax, curves: list[Curves]) -> None:
    try:
        common = float(matched(*curves).grid[-1]) if len(curves) > 1 else None
    except NotJudged:
        return
    if common is not None and any(len(c.grid) and c.grid[-1] > common for c in curves):
        ax.axvline(common, color="black", lw=0.8, ls="--", label=f"compared at {fmt(common)}")


def _random_line(runs: Runs, preset: str, methods: list, x_axis: str) -> pd.DataFrame | None:
    """A flat line at the random policy's mean episode return over the curves' x range; None (and
    a gap) when the data run is missing or ran on another simulator engine than the curves."""
    exp = runs.experiment(preset)
    trial = runs.first_with(exp, "metrics/dataset.json")
    meta = runs.json(exp, trial, "metrics/dataset.json") if trial else None
    if not meta or not isinstance(meta.get("episode_return_mean"), (int, float)):
        return None
    backends = {c.experiment.cfg("env.backend") for _, c in methods if c.n}
    if backends != {trial.cfg("env.backend")}:
        runs.gap(exp, trial, f"random-policy returns from env.backend={trial.cfg('env.backend')}, curves from "
                             f"{', '.join(sorted(map(str, backends)))}: no reference line")
        return None
    grid = np.concatenate([c.grid for _, c in methods if c.n])
    label = f"random policy ({meta.get('episodes')} episodes): {fmt(float(meta['episode_return_mean']))}"
    return pd.DataFrame({"series": label, "experiment": preset, "x_axis": x_axis, "x": [grid.min(), grid.max()],
                         "n": meta.get("episodes"), "mean": float(meta["episode_return_mean"]),
                         "std": meta.get("episode_return_std")})


# --------------------------------------------------------------------------- losses
def plateau_epoch(values: np.ndarray, rel: float = 0.01, window: int = 3) -> int | None:
    """First index e (0-based) at which ``values`` ``(E,)`` (a loss per epoch) changed by less than
    ``rel`` of itself over the last ``window`` epochs: |v[e] - v[e - window]| < rel * |v[e - window]|.
    None while it still changes that much (the convergence rule of the suite's V_s budget)."""
    for e in range(window, len(values)):
        if abs(values[e] - values[e - window]) < rel * abs(values[e - window]):
            return e
    return None


def loss_curves(runs: Runs, entry: Entry, opts: Options, *, model: str, metric: str) -> Output:
    """``train_<metric>`` (blue) and ``val_<metric>`` (red) per epoch of the ``model``
    (``state``/``action``) rows of ``metrics/repr_train.jsonl``. Trials sharing one trained
    representation log identical curves; each distinct model counts once."""
    source = entry.sources[0]
    exp = runs.experiment(source.experiment)
    distinct: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for trial in exp.trials:
        rows = sorted((r for r in runs.records(exp, trial, "repr_train")
                       if r.get("model") == model and isinstance(r.get("epoch"), int)), key=lambda r: r["epoch"])
        if not rows:
            runs.gap(exp, trial, f"metrics/repr_train.jsonl: no rows for model={model}")
            continue
        curve = tuple(np.array([_value(r, f"{split}_{metric}") for r in rows]) for split in ("train", "val"))
        epochs = np.array([r["epoch"] for r in rows], dtype=float)
        distinct.setdefault((epochs.tobytes(), curve[0].tobytes(), curve[1].tobytes()), (epochs, *curve))
    title = f"{entry.title} ({_budgets(runs, entry)}, {plural(len(exp.trials), 'run')})"
    trials = {source.label: len(distinct)}
    if not distinct:
        return empty_output(runs, entry, title)
    plateaus = [plateau_epoch(c[2]) for c in distinct.values()]
    title += "; validation loss " + ", ".join(
        "still changing > 1% over 3 epochs" if p is None else f"within 1% over 3 epochs from epoch {p + 1}"
        for p in plateaus)
    fig = new_figure(entry.size)
    ax = fig.add_subplot()
    frames = []
    for split, color, name in ((1, BASE_BLUE, "train"), (2, PLLS_RED, "validation")):
        grid, values = align([(c[0], c[split]) for c in distinct.values()])
        frame = band_frame(name, source.experiment, "epoch", grid, values)
        draw_band(ax, frame, color, name)
        frames.append(frame)
    data = pd.concat(frames, ignore_index=True)
    if (data["mean"] > 0).all() and data["mean"].max() / data["mean"].min() > 100:
        ax.set_yscale("log")  # MSEs falling over decades: a linear axis would hide the tail
    ax.set_xlabel("epoch")
    ax.set_ylabel({"recon_mse": "reconstruction loss (MSE)", "loss": "loss (negative ELBO)"}.get(metric, metric))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    suptitle(fig, entry.ref, title, trials, unit="trained model")
    return Output(fig, data, trials=trials)


def _value(row: dict, key: str) -> float:
    value = row.get(key)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else np.nan
