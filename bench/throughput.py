"""Throughput of every kind of work a profile runs, for ``reproduce.sh --dry-run``'s cost estimate.

    nice -n 10 .venv/bin/python bench/throughput.py                 # every preset (about 15 minutes)
    nice -n 10 .venv/bin/python bench/throughput.py --keys collect/ repr_action/   # refresh some keys
    nice -n 10 .venv/bin/python bench/throughput.py --backend envpool --presets carracing_data carracing_plls_ppo

Measures, on this machine, the rates ``plls_bench/pipeline/plan.py`` multiplies work by: random-policy
collection (env steps/s, ``collect/<env>``), V_s / V_a training (samples/s over one epoch of
random inputs of the right shape, ``repr_state|repr_action/<env>``), policy learning and
evaluation of each PPO and DBC preset (env steps/s, ``train/<preset>``, ``eval/<preset>``) and
studies (runs/s, ``study/<preset>``). PPO and DBC numbers come from ``bench/ppo_throughput.py``
and ``bench/dbc_throughput.py`` at shortened horizons. Writes ``bench/throughput.json`` (merged
with the keys not measured this time) and this script's section of ``docs/benchmarks.md``.

``--compare`` measures the same keys but leaves ``bench/throughput.json`` alone: it writes a section
of ``docs/benchmarks.md`` with each key's rate here beside the table's, the machine each was measured on
and their ratio, so a campaign on another kind of machine knows how far the dry run's CPU-hours
apply there (rates measured per wall second are compared but flagged: their ratio mixes clocks).

``--clock cpu`` (the default) times work in the process's CPU seconds (all its threads, envpool's
included), which is what the dry run adds up as CPU-hours and what other load on a shared machine
disturbs least; ``--clock wall`` times it in wall seconds, as rates measured before 2026-11-25 were.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import date
from pathlib import Path
from typing import NamedTuple

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench import dbc_throughput, ppo_throughput  # noqa: E402
from bench.benchmarks_md import announce, machine, write_section  # noqa: E402
from bench.representations import TINY_REPR, prepare_representations  # noqa: E402
from plls_bench.config import PRECISIONS, Config  # noqa: E402
from plls_bench.config.tasks import ENV_BACKENDS, ENVPOOL_GYM_IDS  # noqa: E402
from plls_bench.core.atomic_files import atomic_write_json
from plls_bench.pipeline.plan import list_presets  # noqa: E402
from plls_bench.pipeline.rates import THROUGHPUT_FILE  # noqa: E402
from plls_bench.pipeline.rates import rate_keys as plan_rate_keys
from plls_bench.pipeline.runner_registry import runner_spec  # noqa: E402
from plls_bench.rundirs.composition import compose  # noqa: E402

SECTION = "throughput"
COMPARE_SECTION = "throughput_compare"  # one per --backend: a run measures one backend's keys
CLOCKS: dict[str, Callable[[], float]] = {"cpu": time.process_time, "wall": time.perf_counter}


def rate_unit(what: str, clock: str) -> str:
    """``env steps/s`` for wall-clock rates, ``env steps per CPU-s`` for CPU-clock ones."""
    return f"{what}/s" if clock == "wall" else f"{what} per CPU-s"


def _config(preset: str, budget: str, runs_dir: str, *overrides: str) -> Config:
    return compose([f"+experiment={preset}", f"budget={budget}", f"runs_dir={runs_dir}", "progress=false",
                    *overrides])


def collect_rate(cfg: Config, steps: int, clock: str) -> float:
    """Env steps per second of ``clock`` of random-policy collection (one wave of parallel episodes)."""
    from plls_bench.data.collect import collect_random_policy

    episodes = cfg.env.data_num_envs
    start = CLOCKS[clock]()
    collect_random_policy(cfg.env, episodes, steps, seed=0, progress=False)
    return episodes * steps / (CLOCKS[clock]() - start)


def repr_rate(cfg: Config, which: str, samples: int, clock: str) -> float:
    """Training samples per second of ``clock`` of one V_s / V_a epoch on random inputs of the task's shape."""
    from plls_bench.repr.fit import Split, fit, torch_threads
    from plls_bench.repr.train import action_dim, new_model, training_threads
    from plls_bench.rundirs.devices import resolve_device

    mcfg = getattr(cfg.repr, which)
    rng = np.random.default_rng(0)
    if which == "action":
        n_actions = action_dim(cfg)
        array = rng.uniform(-1, 1, (samples + 64, n_actions)).astype(np.float32)
    else:
        n_actions = None
        size = cfg.env.image_size  # frames are stored channels-first, as uint8
        array = rng.integers(0, 256, (samples + 64, 3, size, size), dtype=np.uint8)
    train, val = Split(array, np.arange(samples)), Split(array, np.arange(samples, samples + 64))
    with tempfile.TemporaryDirectory() as tmp, torch_threads(training_threads(cfg, which)):
        model = new_model(cfg, which, n_actions)
        start = CLOCKS[clock]()
        fit(model, train, val, epochs=1, batch_size=mcfg.batch_size, learning_rate=mcfg.learning_rate, seed=0,
            device=resolve_device(cfg.device), resume=Path(tmp) / "resume.pt", progress=False, desc="")
        return samples / (CLOCKS[clock]() - start)


def study_rate(cfg: Config, runs_dir: str, clock: str) -> float:
    """Runs per second of ``clock`` of a study (its V_a built beforehand: that is costed as repr_action)."""
    from plls_bench.pipeline.execute import execute

    prepare_representations(cfg)
    with tempfile.TemporaryDirectory() as tmp:
        start = CLOCKS[clock]()
        execute(cfg, Path(tmp) / "study")
        return 1.0 / (CLOCKS[clock]() - start)


def _collect(cfg: Config, keys: list[str], args: argparse.Namespace,
             engine: tuple[str, ...]) -> list[tuple[float, str]]:
    return [(collect_rate(cfg, args.collect_steps, args.clock), rate_unit("env steps", args.clock))]


def _repr(cfg: Config, keys: list[str], args: argparse.Namespace, engine: tuple[str, ...]) -> list[tuple[float, str]]:
    samples = {"state": args.state_samples, "action": args.action_samples}
    models = [key.split("/")[0].removeprefix("repr_") for key in keys]  # repr_state/<env> -> state
    return [(repr_rate(cfg, which, samples[which], args.clock), rate_unit("samples", args.clock))
            for which in models]


def _study(cfg: Config, keys: list[str], args: argparse.Namespace, engine: tuple[str, ...]) -> list[tuple[float, str]]:
    return [(study_rate(cfg, args.runs, args.clock), rate_unit("runs", args.clock))]


def _ppo(cfg: Config, keys: list[str], args: argparse.Namespace, engine: tuple[str, ...]) -> list[tuple[float, str]]:
    horizon = [f"algo.ppo.n_steps={args.ppo_steps}"] if args.ppo_steps else []
    prepare_representations(_config(cfg.experiment, args.budget, args.runs, *TINY_REPR, *horizon, *engine))
    m = ppo_throughput.measure(cfg.experiment, args.budget, args.ppo_iterations, args.runs,
                               [*TINY_REPR, *horizon, *engine])
    train, acting = (m["cpu_sps"], m["rollout_cpu_sps"]) if args.clock == "cpu" else (m["sps"], m["rollout_sps"])
    return [(train, rate_unit("env steps", args.clock)), (acting, rate_unit("env steps", args.clock))]  # eval: acting


def _dbc(cfg: Config, keys: list[str], args: argparse.Namespace, engine: tuple[str, ...]) -> list[tuple[float, str]]:
    prepare_representations(_config(cfg.experiment, args.budget, args.runs, *TINY_REPR, *engine))
    m = dbc_throughput.measure(cfg.experiment, args.budget, 1, args.dbc_steps, args.dbc_updates, args.runs,
                               [*TINY_REPR, *engine])
    acting, update_s = (m["env_cpu_sps"], m["cpu_s"]) if args.clock == "cpu" else (m["env_sps"], m["update_s"])
    # one update per agent step, i.e. per action_repeat env steps
    seconds_per_env_step = 1.0 / acting + update_s / cfg.env.action_repeat
    unit = rate_unit("env steps", args.clock)
    return [(1.0 / seconds_per_env_step, unit), (acting, unit)]


class Measurement(NamedTuple):
    """How one kind of work is timed: one value per rate key of ``kinds`` (``plls_bench.pipeline.rates.rate_keys``)."""

    measure: Callable[[Config, list[str], argparse.Namespace, tuple[str, ...]], list[tuple[float, str]]]
    kinds: tuple[str, ...]  # the rate kinds it gives, in the order ``measure`` returns them
    env_bound: bool         # steps the env: measured per backend


# Measurement name -> how it is timed. A runner names its measurement on its RunnerSpec
# (``measure``); only a runner whose work none of these times adds one here.
MEASURES: dict[str, Measurement] = {
    "collection": Measurement(_collect, ("collect",), True),
    "vae_epoch": Measurement(_repr, ("repr_state", "repr_action"), False),
    "study_run": Measurement(_study, ("run",), False),
    "ppo_iterations": Measurement(_ppo, ("train", "eval"), True),
    "dbc_steps": Measurement(_dbc, ("train", "eval"), True),
}


def rate_keys(cfg: Config) -> list[str]:
    """The rate keys a preset's measurement gives: those of the plan's keys for its config that
    its runner's measurement times (env-bound ones per backend)."""
    keys = plan_rate_keys(cfg)
    return [keys[kind] for kind in MEASURES[runner_spec(cfg.runner).measure].kinds if kind in keys]


def preset_rates(preset: str, args: argparse.Namespace) -> dict[str, tuple[float, str]]:
    """Measured rates of ``preset``'s keys that ``args.keys`` selects: key -> (value, unit)."""
    # explicit: a profile may choose another backend
    engine = (f"env.backend={args.backend}", f"precision={args.precision}")
    if args.backend != "gymnasium":
        base = _config(preset, args.budget, args.runs)
        if base.env.gym_id not in ENVPOOL_GYM_IDS or not MEASURES[runner_spec(base.runner).measure].env_bound:
            return {}  # envpool's tasks only, and only work that steps the env
    cfg = _config(preset, args.budget, args.runs, *engine)
    keys = rate_keys(cfg)
    if args.precision != "fp32":  # only rates through conv trunks have per-precision keys
        keys = [key for key in keys if key.endswith(f"@{args.precision}")]
    if not keys or args.keys is not None and not any(k.startswith(tuple(args.keys)) for k in keys):
        return {}
    measure = MEASURES[runner_spec(cfg.runner).measure].measure
    return dict(zip(keys, measure(cfg, keys, args, engine)))


def read_table() -> dict:
    """``bench/throughput.json``, or an empty table when it is missing or unreadable."""
    try:
        return json.loads(THROUGHPUT_FILE.read_text())
    except (OSError, ValueError):
        return {"rates": {}}


def merged(rates: dict[str, tuple[float, str]], command: str, host: str) -> dict:
    """``bench/throughput.json`` with ``rates`` replacing their keys (the others are kept)."""
    data = read_table()
    stamp = {"date": date.today().isoformat(), "command": command, "machine": host}
    for key, (value, unit) in rates.items():
        data["rates"][key] = {"value": round(value, 4), "unit": unit, **stamp}
    data["rates"] = dict(sorted(data["rates"].items()))
    return data


def section(data: dict) -> str:
    rows = [f"| `{key}` | {e['value']:,.4g} | {e['unit']} | {e['date']} | {e['machine']} |"
            for key, e in data["rates"].items()]
    return "\n".join([
        "## Throughput table for cost estimates (`bench/throughput.py` -> `bench/throughput.json`)", "",
        "`reproduce.sh --dry-run` multiplies each preset's work by these rates. Each row names the "
        "machine and load it was measured under; re-run the script on your machine for estimates of it. "
        "Rates per CPU-s (`--clock cpu`, the default since 2026-11-25) count the process's CPU time, which "
        "other load disturbs least; rates per s are wall-clock rates of earlier measurements.",
        "", "| key | rate | unit | measured | machine |", "|---|---|---|---|---|", *rows,
        "", "Commands: " + "; ".join(sorted({f"`{e['command']}`" for e in data["rates"].values()}))])


def compare_section(backend: str) -> str:
    return COMPARE_SECTION if backend == "gymnasium" else f"{COMPARE_SECTION}_{backend}"


def comparison(rates: dict[str, tuple[float, str]], command: str, host: str, backend: str = "gymnasium") -> str:
    """A BENCHMARKS section: each measured key's rate here beside ``bench/throughput.json``'s."""
    table = read_table()["rates"]
    rows = []
    for key, (value, unit) in sorted(rates.items()):
        ref = table.get(key)
        if ref is None:
            rows.append(f"| `{key}` | {value:,.4g} {unit} | (not in the table) | | |")
            continue
        flag = "" if ref["unit"] == unit else " (clocks differ)"
        rows.append(f"| `{key}` | {value:,.4g} {unit} | {ref['value']:,.4g} {ref['unit']} | "
                    f"{value / ref['value']:.2f}{flag} | {ref['date']}, {ref['machine']} |")
    return "\n".join([
        f"## This machine against the throughput table (`bench/throughput.py --compare`, {backend})", "",
        f"Command: `{command}`  ", f"Machine: {host}  ",
        "Each key measured here beside the rate `reproduce.sh --dry-run` uses (`bench/throughput.json`, not "
        "changed by this run). Ratio = here / table: the dry run's CPU-hours for that work are about "
        "1 / ratio times too low on this machine. Ratios across machines are not measured in one run; "
        "read them as a planning factor, not a speed-up.",
        "", "| key | here | table | ratio | table measured on |", "|---|---|---|---|---|", *rows])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--presets", nargs="+", default=None, help="presets to measure (default: all)")
    parser.add_argument("--keys", nargs="+", default=None, help="only rate keys starting with these")
    parser.add_argument("--budget", default="quick", help="budget whose algorithm settings are used")
    parser.add_argument("--backend", default="gymnasium", choices=ENV_BACKENDS,
                        help="env.backend to measure (envpool: the tasks it ships; keys get @envpool)")
    parser.add_argument("--precision", default="fp32", choices=PRECISIONS,
                        help="precision to measure (bf16: the rates through conv trunks, keys get @bf16)")
    parser.add_argument("--clock", default="cpu", choices=list(CLOCKS),
                        help="time work in process CPU seconds (default; what the dry run's CPU-hours add up) "
                             "or wall seconds")
    parser.add_argument("--collect-steps", type=int, default=200, help="steps per env of collection")
    parser.add_argument("--state-samples", type=int, default=500, help="frames in the V_s epoch")
    parser.add_argument("--action-samples", type=int, default=20000, help="actions in the V_a epoch")
    parser.add_argument("--ppo-iterations", type=int, default=1, help="timed PPO iterations")
    parser.add_argument("--ppo-steps", type=int, default=125, help="PPO horizon override (0: the preset's)")
    parser.add_argument("--dbc-steps", type=int, default=50, help="timed DBC acting steps")
    parser.add_argument("--dbc-updates", type=int, default=5, help="timed DBC updates")
    parser.add_argument("--runs", default=str(Path(tempfile.gettempdir()) / "plls_bench_throughput"),
                        help="runs_dir for the artifacts the measurements need")
    parser.add_argument("--no-write", action="store_true", help="print only")
    parser.add_argument("--compare", action="store_true",
                        help="leave bench/throughput.json alone: write this machine's rates beside the table's "
                             "(docs/benchmarks.md section throughput_compare, one per --backend)")
    args = parser.parse_args(argv)
    command = announce("throughput.py", argv)
    rates: dict[str, tuple[float, str]] = {}
    for preset in args.presets or list_presets():
        for key, (value, unit) in preset_rates(preset, args).items():
            rates[key] = (value, unit)
            print(f"{key:40s} {value:12,.4g} {unit}", flush=True)
    if args.compare:
        text = comparison(rates, command, machine(), args.backend)
        print(text, flush=True)
        if not args.no_write:
            write_section(compare_section(args.backend), text)
        return 0
    data = merged(rates, command, machine())
    if not args.no_write:
        atomic_write_json(THROUGHPUT_FILE, data)
        write_section(SECTION, section(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
