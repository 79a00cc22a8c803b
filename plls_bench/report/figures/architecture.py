"""Architecture summaries from the instantiated models (Figs 12 and 17): every module a method
runs, as a chain of layer boxes with output shape and parameter count; trainable layers orange,
frozen ones grey; parameter-free layers (activations) in italics between boxes, as the paper
marks them."""
from __future__ import annotations

import textwrap

import pandas as pd
from matplotlib.patches import FancyBboxPatch

from plls_bench.report.evidence.entry_types import Entry, Options, Output
from plls_bench.report.evidence.load import Runs
from plls_bench.report.figures.plot import empty_output, new_figure, suptitle
from plls_bench.rundirs.run_dir import ARCHITECTURE_FILE, PARAMS_FILE

TRAINABLE, FROZEN = "#fdb863", "#d9d9d9"
LAYER_KEYS = ("name", "type", "output_shape", "params", "trainable")


def _layers(runs: Runs, entry: Entry) -> tuple[pd.DataFrame, dict[str, str]]:
    """Tidy layer table ``(source, module, index, name, type, output_shape, params, trainable)``
    from the lowest seed of each source, and a parameter summary per source."""
    frames, totals = [], {}
    for source in entry.sources:
        exp = runs.experiment(source.experiment)
        trial = runs.first_with(exp, ARCHITECTURE_FILE)
        arch = runs.json(exp, trial, ARCHITECTURE_FILE) if trial else None
        if trial is None or arch is None:
            continue
        for module, layers in arch.items():
            ok = isinstance(layers, list) and all(isinstance(x, dict) and set(LAYER_KEYS) <= set(x)
                                                  for x in layers)
            if not ok:
                runs.gap(exp, trial, f"{ARCHITECTURE_FILE}: module {module!r} is not a list of layers "
                                     f"with {', '.join(LAYER_KEYS)}")
                continue
            frames.append(pd.DataFrame([{"source": source.label, "module": module, "index": i,
                                         **{k: layer[k] for k in LAYER_KEYS}} for i, layer in enumerate(layers)]))
        params = runs.json(exp, trial, PARAMS_FILE)
        if params and isinstance(params.get("total"), int) and isinstance(params.get("trainable"), int):
            totals[source.label] = f"{params['total']:,} parameters, {params['trainable']:,} trainable"
    return (pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=LAYER_KEYS)), totals


def _shape(shape: object) -> str:
    """``[1, 32, 47, 47]`` -> ``32x47x47``: the leading batch dimension of the example input dropped."""
    if not isinstance(shape, (list, tuple)):
        return str(shape)
    dims = list(shape[1:]) if len(shape) > 1 else list(shape)
    return "x".join(str(d) for d in dims)


def _module_order(key: tuple[str, str]) -> int:
    """architecture.json's keys come sorted; draw a method's modules in data-flow order."""
    name = key[1].lower()
    return 0 if "encoder" in name else 2 if "decoder" in name else 1


def _chain(layers: pd.DataFrame) -> list[tuple[pd.Series | None, list[str]]]:
    """Layers with parameters, each with the parameter-free layers (activations) after it."""
    chain: list[tuple[pd.Series | None, list[str]]] = [(None, [])]
    for _, layer in layers.iterrows():
        if layer["params"] > 0:
            chain.append((layer, []))
        else:
            chain[-1][1].append(str(layer["type"]))
    return chain if chain[0][1] else chain[1:]


def _draw_module(ax, layers: pd.DataFrame, title: str) -> None:
    """One module as a left-to-right chain of boxes in axes coordinates; each box's activations
    in italics under it."""
    ax.set_axis_off()
    ax.set(xlim=(0, 1), ylim=(0, 1))
    ax.text(0.0, 0.95, title, fontsize=8, weight="bold", va="top")
    chain = _chain(layers)
    width = min(0.96 / max(len(chain), 1), 0.16)  # a short module keeps boxes of readable size
    for slot, (layer, italic) in enumerate(chain):
        x = 0.02 + slot * width
        if layer is not None:
            colour = TRAINABLE if layer["trainable"] else FROZEN
            ax.add_patch(FancyBboxPatch((x, 0.15), width * 0.86, 0.55, boxstyle="round,pad=0.005",
                                        facecolor=colour, edgecolor="0.3", lw=0.6))
            label = f"{layer['type']}\n{_shape(layer['output_shape'])}\n{int(layer['params']):,} p"
            ax.text(x + width * 0.43, 0.42, label, ha="center", va="center", fontsize=max(5, min(8, 60 * width)))
        if italic:
            ax.text(x + width * 0.43, 0.04, textwrap.shorten(" ".join(italic), 40), fontsize=6,
                    style="italic", ha="center")


def architecture(runs: Runs, entry: Entry, opts: Options) -> Output:
    """Every module of every source as a row of layer boxes; the title gives parameter totals."""
    data, totals = _layers(runs, entry)
    if data.empty:
        return empty_output(runs, entry, entry.title)
    trials = {s.label: int((data["source"] == s.label).any()) for s in entry.sources}
    order = {s.label: i for i, s in enumerate(entry.sources)}
    modules = sorted(dict.fromkeys(zip(data["source"], data["module"])),
                     key=lambda m: (order[m[0]], _module_order(m)))
    fig = new_figure(entry.size)
    axes = fig.subplots(max(len(modules), 4), 1, squeeze=False)[:, 0]  # rows of one height, however few
    for ax in axes[len(modules):]:
        ax.set_axis_off()
    for ax, (label, module) in zip(axes, modules):
        rows = data[(data["source"] == label) & (data["module"] == module)]
        weighted = rows[rows["params"] > 0]["trainable"]  # parameter-free layers are neither
        frozen = "trainable" if weighted.all() else "frozen" if not weighted.any() else "mixed"
        _draw_module(ax, rows, f"{label}: {module} ({int(rows['params'].sum()):,} parameters, {frozen})")
    summary = "; ".join(f"{label}: {text}" for label, text in totals.items())
    suptitle(fig, entry.ref, f"{entry.title}\n{summary}" if summary else entry.title, trials, unit="run")
    data = data.assign(output_shape=data["output_shape"].map(_shape))
    return Output(fig, data, trials=trials)
