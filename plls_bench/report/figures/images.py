"""Image figures: filmstrips of learned policies (Figs 11, 19, 22), V_s originals vs
reconstructions (Fig 14) and V_a actions vs reconstructed actions (Fig 16)."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.figures.plot import PURPLE_DARK, PURPLE_LIGHT, empty_output, letter, new_figure, suptitle

MAX_FRAMES = 36  # more frames than this get too small to read on one page
ACTION_NAMES = {3: ("steering", "gas", "brake")}



def _grid(count: int, size: tuple[float, float], aspect: float) -> tuple[int, int]:
    """Rows and columns that make ``count`` frames of width/height ``aspect`` largest on ``size``."""
    width, height = size[0], size[1] * 0.8  # the title takes the top of the canvas

    def frame_width(cols: int) -> float:
        return min(width / cols, height / math.ceil(count / cols) * aspect)

    cols = max(range(1, count + 1), key=frame_width)
    return math.ceil(count / cols), cols


def _mosaic(images: np.ndarray, rows: int, cols: int, pad: int) -> np.ndarray:
    """Frames ``(k, H, W, 3)`` tiled row by row on a white canvas with ``pad`` pixels between."""
    k, height, width, _ = images.shape
    canvas = np.full((rows * (height + pad), cols * (width + pad), 3), 255, dtype=np.uint8)
    for i, image in enumerate(images):
        r, c = divmod(i, cols)
        canvas[r * (height + pad):r * (height + pad) + height, c * (width + pad):c * (width + pad) + width] = image
    return canvas


def filmstrip(runs: Runs, entry: Entry, opts: Options) -> Output:
    """``filmstrip/frames.npz`` (frames ``(k, H, W, 3)`` uint8) as a strip of images labelled
    (a), (b), ... with their time step, and ``filmstrip.json``'s numbers in the title."""
    source = entry.sources[0]
    exp = runs.experiment(source.experiment)
    trial = runs.first_with(exp, "filmstrip/frames.npz")
    frames = runs.arrays(exp, trial, "filmstrip/frames.npz", {"frames": (None, None, None, 3)}) if trial else None
    meta = runs.json(exp, trial, "filmstrip/filmstrip.json") if trial else None
    title = f"{entry.title} ({'budget ' + exp.budget if exp.budget else 'no runs'}"
    if frames is None or trial is None:
        return empty_output(runs, entry, title + ")")
    images = frames["frames"][:MAX_FRAMES]
    meta = meta or {}
    steps = list(meta.get("frame_steps") or [])
    steps = steps if len(steps) >= len(images) else [None] * len(images)
    interval = meta.get("interval")
    episode_return, total = meta.get("episode_return"), len(frames["frames"])
    details = [f"seed {trial.seed}", f"one frame every {interval} steps" if interval else None,
               f"return {episode_return:.1f}" if isinstance(episode_return, (int, float)) else None,
               f"goal after {meta['steps_to_goal']} steps" if meta.get("steps_to_goal") is not None else None,
               f"first {MAX_FRAMES} of {total} frames" if total > MAX_FRAMES else None]
    title += ", " + ", ".join(d for d in details if d) + ")"
    fig = new_figure(entry.size)
    rows, cols = _grid(len(images), entry.size, images.shape[2] / images.shape[1])
    height, width = images.shape[1:3]
    pad = max(2, height // 5)  # room for each frame's label
    ax = fig.add_subplot()
    ax.imshow(_mosaic(images, rows, cols, pad), interpolation="antialiased")
    ax.set_axis_off()
    for i in range(len(images)):  # one axes for the whole strip: labels are text on it
        r, c = divmod(i, cols)
        ax.text(c * (width + pad), r * (height + pad) + height + pad * 0.1, letter(i) +
                ("" if steps[i] is None else f" t={steps[i]}"), fontsize=7, va="top")
    suptitle(fig, entry.ref, title, {source.label: 1}, unit="run")
    data = pd.DataFrame({"frame": np.arange(len(images)), "label": [letter(i) for i in range(len(images))],
                         "step": steps[:len(images)]})
    return Output(fig, data, trials={source.label: 1})


def state_reconstructions(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Fig 14: each original frame beside V_s's reconstruction, labelled road / grass."""
    source = entry.sources[0]
    exp = runs.experiment(source.experiment)
    relpath = "samples/state_reconstructions.npz"
    trial = runs.first_with(exp, relpath)
    shapes = {"originals": (None, 3, 96, 96), "reconstructions": (None, 3, 96, 96), "labels": (None,)}
    a = runs.arrays(exp, trial, relpath, shapes) if trial else None
    title = f"{entry.title} ({'budget ' + exp.budget if exp.budget else 'no runs'}"
    if a is None or trial is None or not len(a["originals"]) == len(a["reconstructions"]) == len(a["labels"]):
        return empty_output(runs, entry, title + ")")
    missing = sorted({"road", "grass"} - set(a["labels"].astype(str)))
    if missing:  # the paper shows the car on the road and on the grass
        runs.gap(exp, trial, f"{relpath}: no frame labelled {' or '.join(missing)}")
    fig = new_figure(entry.size)
    k = len(a["originals"])
    for i in range(k):
        where = f"car on the {a['labels'][i]}"
        for j, (key, name) in enumerate((("originals", "original"), ("reconstructions", "reconstructed"))):
            ax = fig.add_subplot(1, 2 * k, 2 * i + j + 1)
            ax.imshow(np.transpose(a[key][i], (1, 2, 0)))  # stored channel-first, shown HWC
            ax.set_axis_off()
            ax.set_title(f"{letter(2 * i + j)} {name}\n({where})", fontsize=8)
    suptitle(fig, entry.ref, f"{title}, seed {trial.seed})", {source.label: 1}, unit="run")
    diff = (a["originals"].astype(float) - a["reconstructions"].astype(float)) / 255.0
    data = pd.DataFrame({"index": np.arange(k), "label": a["labels"].astype(str),
                         "pixel_mse": (diff ** 2).reshape(k, -1).mean(axis=1)})
    return Output(fig, data, trials={source.label: 1})


def action_reconstructions(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Fig 16: the first test actions (dark purple) and V_a's reconstructions (light purple),
    one panel per action dimension."""
    source = entry.sources[0]
    exp = runs.experiment(source.experiment)
    relpath = "samples/action_reconstructions.npz"
    trial = runs.first_with(exp, relpath)
    shapes: dict[str, tuple[int | None, ...]] = {"actions": (None, None), "reconstructions": (None, None)}
    a = runs.arrays(exp, trial, relpath, shapes) if trial else None
    title = f"{entry.title} ({'budget ' + exp.budget if exp.budget else 'no runs'}"
    if a is None or trial is None or a["actions"].shape != a["reconstructions"].shape:
        return empty_output(runs, entry, title + ")")
    n, dims = a["actions"].shape
    names = ACTION_NAMES.get(dims, tuple(f"a[{i}]" for i in range(dims)))
    fig = new_figure(entry.size)
    axes = fig.subplots(dims, 1, sharex=True, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        ax.plot(a["actions"][:, i], color=PURPLE_DARK, lw=1.0, label="original")
        ax.plot(a["reconstructions"][:, i], color=PURPLE_LIGHT, lw=1.0, label="reconstructed")
        ax.set_ylabel(names[i])
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncols=2)
    axes[-1].set_xlabel("test action index")
    mse = float(np.mean((a["actions"] - a["reconstructions"]) ** 2))
    suptitle(fig, entry.ref, f"{title}, seed {trial.seed}, {n} test actions, MSE {mse:.3g})",
             {source.label: 1}, unit="run")
    data = pd.DataFrame({"index": np.tile(np.arange(n), dims), "dim": np.repeat(names, n),
                         "original": a["actions"].T.ravel(), "reconstructed": a["reconstructions"].T.ravel()})
    return Output(fig, data, trials={source.label: 1})
