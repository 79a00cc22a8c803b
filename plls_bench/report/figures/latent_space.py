"""MountainCar latent-space studies (Figs 7, 8, 9): 3-D scatters of action representations e with
RGB colouring, and the state effect of raw vs reconstructed actions. Arrays follow docs/architecture.md's
``studies/<study>.npz`` contract; one study run is drawn (the lowest seed that has it). A V_a
with a latent size other than the paper's 3 is drawn in its first three principal components
(fewer dims are padded with zeros), and the axes say so."""
from __future__ import annotations

import numpy as np
import pandas as pd

from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.evidence.trials import Trial
from plls_bench.report.figures.plot import (
    BLUE_DARK,
    BLUE_LIGHT,
    PURPLE_DARK,
    PURPLE_LIGHT,
    empty_output,
    letter,
    new_figure,
    rgb_colours,
    suptitle,
)

STUDY_SHAPES: dict[str, dict[str, tuple[int | None, ...]]] = {  # None: any size (latent dims: D)
    "multistep": {"actions": (None,), "mu": (None, None), "e": (None, None), "decoded": (None,),
                  "states_raw": (None, 2), "states_decoded": (None, 2)},
    "onestep": {"actions": (None,), "mu": (None, None), "e": (None, None), "decoded": (None,),
                "next_states_raw": (None, 2), "next_states_decoded": (None, 2), "s0": (2,)},
    "generalisation": {"actions": (None,), "mu": (None, None), "std": (None, None), "e": (None, None, None),
                       "decoded": (None, None), "next_states": (None, None, 2), "s0": (2,)},
}
STATE_LABELS = ("position x", "velocity ẋ")
# The numbers of metrics/study.json shown in a title: one per claim of Sec. 5.1 where present.
HEADLINE = ("structure/spearman_action_latent_distance", "structure/left_right_separability",
            "recon/mean_abs_action_error", "dynamics/state_error_vs_shuffled")


def _load(runs: Runs, entry: Entry, study: str) -> tuple[Trial | None, dict[str, np.ndarray] | None, str]:
    exp = runs.experiment(entry.sources[0].experiment)
    relpath = f"studies/{study}.npz"
    trial = runs.first_with(exp, relpath)
    arrays = runs.arrays(exp, trial, relpath, STUDY_SHAPES[study]) if trial else None
    problem = _mismatch(study, arrays) if arrays is not None else None
    if trial and problem:
        runs.gap(exp, trial, f"{relpath}: {problem}")
        arrays = None
    summary = runs.json(exp, trial, "metrics/study.json") if trial and arrays is not None else None
    scalars = {k: v for k, v in (summary or {}).items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    keys = [k for k in HEADLINE if k in scalars] or sorted(scalars)[:4]
    numbers = [f"{k} = {scalars[k]:.4g}" for k in keys]
    seed = f", seed {trial.seed}" if trial else ""
    lines = ["; ".join(numbers[i:i + 2]) for i in range(0, len(numbers), 2)]
    title = "\n".join([f"{entry.title} ({exp.budget_text}{seed})", *lines])
    return trial, arrays, title


def _mismatch(study: str, a: dict[str, np.ndarray]) -> str | None:
    """Arrays of one study must agree in length: N actions (N + 1 states along a trajectory)."""
    n = len(a["actions"])
    want = {key: n + (key.startswith("states_")) for key in a if key != "s0"}
    bad = [f"{key} has {len(a[key])} rows" for key, rows in want.items() if len(a[key]) != rows]
    dims = {key: a[key].shape[-1] for key in ("mu", "std", "e") if key in a}
    if len(set(dims.values())) > 1:
        bad.append("latent sizes differ: " + ", ".join(f"{k} {d}" for k, d in dims.items()))
    if study == "generalisation" and not a["e"].shape[1] == a["decoded"].shape[1] == a["next_states"].shape[1]:
        bad.append("e, decoded and next_states hold different numbers of samples")
    return f"{'; '.join(bad)} (actions has {n})" if bad else None



def latent_3d(points: np.ndarray) -> tuple[np.ndarray, tuple[str, str, str]]:
    """Latents ``(N, D)`` as ``(N, 3)`` and axis names: the paper's (l, m, n) when D = 3, the
    first three principal components when D > 3, zero-padded when D < 3."""
    d = points.shape[1]
    if d == 3:
        return points, ("l", "m", "n")
    if d < 3:
        names = tuple(("l", "m", "n")[i] if i < d else "(none)" for i in range(3))
        return np.pad(points, ((0, 0), (0, 3 - d))), names  # type: ignore[return-value]
    centred = points - points.mean(axis=0)
    _, _, axes = np.linalg.svd(centred, full_matrices=False)
    return centred @ axes[:3].T, (f"PC1 of {d}", f"PC2 of {d}", f"PC3 of {d}")


def _scatter3d(fig, position: int, e: np.ndarray, colours, title: str, shape=(2, 2), names=("l", "m", "n")):
    ax = fig.add_subplot(*shape, position, projection="3d")
    ax.scatter(e[:, 0], e[:, 1], e[:, 2], c=colours, s=6, depthshade=False)
    ax.set_xlabel(names[0]), ax.set_ylabel(names[1]), ax.set_zlabel(names[2])
    ax.set_box_aspect(None, zoom=0.85)  # room for the z label inside the panel
    ax.set_title(title, fontsize=8)
    return ax


def _phase(ax, states: np.ndarray, title: str, limits) -> None:
    ax.plot(states[:, 0], states[:, 1], color="0.7", lw=0.6)
    ax.scatter(states[:, 0], states[:, 1], c=np.arange(len(states)), cmap="viridis", s=4)
    ax.set(xlabel=STATE_LABELS[0], ylabel=STATE_LABELS[1], xlim=limits[0], ylim=limits[1])
    ax.set_title(title, fontsize=8)


def _limits(*arrays: np.ndarray):
    both = np.concatenate([a.reshape(-1, 2) for a in arrays])
    pad = 0.05 * (both.max(axis=0) - both.min(axis=0) + 1e-9)
    return [(both[:, i].min() - pad[i], both[:, i].max() + pad[i]) for i in range(2)]


def multistep(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Fig 7: (a) e with points 501..1000 red, (b) with 401..600 red, others RGB = (l, m, n)
    normalised; (c), (d) the (x, x_dot) trajectory under raw and reconstructed actions."""
    trial, a, title = _load(runs, entry, "multistep")
    if a is None:
        return empty_output(runs, entry, title)
    n = len(a["e"])
    e3, axes = latent_3d(a["e"])
    fig = new_figure(entry.size)
    masks = (np.arange(n) >= n // 2, (np.arange(n) >= 2 * n // 5) & (np.arange(n) < 3 * n // 5))
    names = ("partition 500:500, second half red", "partition 400:200:400, middle red")
    for i, (mask, name) in enumerate(zip(masks, names)):
        colours = rgb_colours(e3)
        colours[mask] = (1.0, 0.0, 0.0)
        _scatter3d(fig, i + 1, e3, colours, f"{letter(i)} action representations, {name}", names=axes)
    limits = _limits(a["states_raw"], a["states_decoded"])
    _phase(fig.add_subplot(2, 2, 3), a["states_raw"], "(c) state under raw actions", limits)
    _phase(fig.add_subplot(2, 2, 4), a["states_decoded"], "(d) state under reconstructed actions", limits)
    suptitle(fig, entry.ref, title, {entry.sources[0].label: 1}, unit="run")
    data = pd.concat([
        pd.DataFrame({"panel": "ab", "index": np.arange(n), "action": a["actions"], "decoded": a["decoded"],
                      **{f"e_{c}": e3[:, i] for i, c in enumerate("lmn")},
                      "red_a": masks[0], "red_b": masks[1]}),
        *(pd.DataFrame({"panel": p, "index": np.arange(len(s)), "x": s[:, 0], "x_dot": s[:, 1]})
          for p, s in (("c", a["states_raw"]), ("d", a["states_decoded"])))], ignore_index=True)
    return Output(fig, data, trials={entry.sources[0].label: 1})


def onestep(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Fig 8: (a) e coloured RGB, (b) actions in [-1, 0) purple and (0, 1] blue, (c), (d) the
    states one step after s0 under raw and reconstructed actions."""
    trial, a, title = _load(runs, entry, "onestep")
    if a is None:
        return empty_output(runs, entry, title)
    left = a["actions"] < 0
    side = np.where(left[:, None], np.array([[0.45, 0.0, 0.55]]), np.array([[0.12, 0.23, 0.8]]))
    fig = new_figure(entry.size)
    e3, axes = latent_3d(a["e"])
    _scatter3d(fig, 1, e3, rgb_colours(e3), "(a) action representations, RGB = (l, m, n)", names=axes)
    _scatter3d(fig, 2, e3, side, "(b) left actions purple, right actions blue", names=axes)
    limits = _limits(a["next_states_raw"], a["next_states_decoded"], a["s0"][None])
    for pos, key, name in ((3, "next_states_raw", "(c) transitions under raw actions"),
                           (4, "next_states_decoded", "(d) transitions under reconstructed actions")):
        ax = fig.add_subplot(2, 2, pos)
        ax.scatter(a[key][:, 0], a[key][:, 1], c=side, s=5)
        ax.scatter(*a["s0"], marker="*", s=80, color="black", label="s0")
        ax.set(xlabel=STATE_LABELS[0], ylabel=STATE_LABELS[1], xlim=limits[0], ylim=limits[1])
        ax.set_title(name, fontsize=8)
        ax.legend(fontsize=7)
    suptitle(fig, entry.ref, title, {entry.sources[0].label: 1}, unit="run")
    raw, decoded = a["next_states_raw"], a["next_states_decoded"]
    data = pd.DataFrame({"index": np.arange(len(left)), "action": a["actions"], "decoded": a["decoded"],
                         **{f"e_{c}": e3[:, i] for i, c in enumerate("lmn")},
                         "x_raw": raw[:, 0], "x_dot_raw": raw[:, 1], "x_decoded": decoded[:, 0],
                         "x_dot_decoded": decoded[:, 1]})
    return Output(fig, data, trials={entry.sources[0].label: 1})


def generalisation(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Fig 9: (a) raw actions (dark) and the actions decoded from 10 samples e = mu + std * eps
    each (light), (b) the samples e, (c) the states reached with the reconstructed actions."""
    trial, a, title = _load(runs, entry, "generalisation")
    if a is None:
        return empty_output(runs, entry, title)
    k, samples = a["decoded"].shape
    left = a["actions"] < 0
    dark = [PURPLE_DARK if is_left else BLUE_DARK for is_left in left]
    light = np.repeat([PURPLE_LIGHT if is_left else BLUE_LIGHT for is_left in left], samples)
    fig = new_figure(entry.size)
    ax = fig.add_subplot(1, 3, 1)
    ax.scatter(np.repeat(np.arange(1, k + 1), samples), a["decoded"].ravel(), c=light, s=10, label="reconstructed")
    ax.scatter(np.arange(1, k + 1), a["actions"], c=dark, s=30, marker="D", label="raw")
    ax.set(xlabel="sampled action", ylabel="action a")
    ax.set_title("(a) raw and reconstructed actions", fontsize=8)
    ax.legend(fontsize=7)
    e3, axes = latent_3d(a["e"].reshape(-1, a["e"].shape[-1]))
    _scatter3d(fig, 2, e3, light, "(b) samples e in latent space", shape=(1, 3), names=axes)
    ax = fig.add_subplot(1, 3, 3)
    ax.scatter(a["next_states"][..., 0].ravel(), a["next_states"][..., 1].ravel(), c=light, s=10)
    ax.scatter(*a["s0"], marker="*", s=80, color="black", label="s0")
    ax.set(xlabel=STATE_LABELS[0], ylabel=STATE_LABELS[1])
    ax.set_title("(c) states after reconstructed actions", fontsize=8)
    ax.legend(fontsize=7)
    suptitle(fig, entry.ref, title, {entry.sources[0].label: 1}, unit="run")
    states = a["next_states"].reshape(-1, 2)
    data = pd.DataFrame({"action_index": np.repeat(np.arange(k), samples),
                         "sample": np.tile(np.arange(samples), k),
                         "action": np.repeat(a["actions"], samples), "decoded": a["decoded"].ravel(),
                         **{f"e_{c}": e3[:, i] for i, c in enumerate("lmn")},
                         "x_next": states[:, 0], "x_dot_next": states[:, 1]})
    return Output(fig, data, trials={entry.sources[0].label: 1})
