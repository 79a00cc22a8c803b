"""CarRacing env steps per second of the suite's vector env, gymnasium vs envpool, in one run.

    nice -n 10 .venv/bin/python bench/env_speed.py                 # 16 envs, 1000 vector steps each
    nice -n 10 .venv/bin/python bench/env_speed.py --steps 200 --no-write

Each row steps ``plls_bench.envs.make_vec_env`` (what the ``ppo`` runner steps: channel-first float
frames) with uniform random actions; envs reset as they finish, as in training. Settings:
gymnasium in one process (``DummyVecEnv``, 1 thread) and in one subprocess per env
(``algo.ppo.vec_env=subproc``: 16 processes on the machine's cores); envpool with 1 and 2 worker
threads (``env.backend_threads``). The rows run interleaved (A B C D A B C D ...) so that a change
of load on a shared machine hits every setting alike; ratios are against gymnasium in one thread.

Also measures the bound a PL-LS policy's rollout cannot pass however fast the env is: V_s's
encoder forward on a batch of 16 frames (frames/s per torch thread), the work ``LatentObservation``
adds per vector step.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, finish_section  # noqa: E402
from plls_bench.envs import make_vec_env  # noqa: E402
from plls_bench.rundirs.composition import compose  # noqa: E402

SECTION = "env_speed"
SETTINGS = {  # name -> (overrides, subprocess vec env)
    "gymnasium, 1 thread (DummyVecEnv)": (["env.backend=gymnasium"], False),
    "gymnasium, 1 process per env (SubprocVecEnv)": (["env.backend=gymnasium"], True),
    "envpool, 1 thread": (["env.backend=envpool", "env.backend_threads=1"], False),
    "envpool, 2 threads": (["env.backend=envpool", "env.backend_threads=2"], False),
}


def _steps_per_second(venv, steps: int, rng: np.random.Generator) -> float:
    low, high = venv.action_space.low, venv.action_space.high
    actions = rng.uniform(low, high, size=(steps, venv.num_envs, len(low))).astype(np.float32)
    venv.reset()
    start = time.perf_counter()
    for t in range(steps):
        venv.step(actions[t])
    return steps * venv.num_envs / (time.perf_counter() - start)


def env_rates(n_envs: int, steps: int, rounds: int) -> dict[str, list[float]]:
    """Env steps/s of every setting, ``rounds`` interleaved measurements each."""
    rates: dict[str, list[float]] = {name: [] for name in SETTINGS}
    venvs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (overrides, subproc) in SETTINGS.items():
            cfg = compose(["+experiment=carracing_ppo", "budget=quick", f"runs_dir={tmp}", *overrides])
            venvs[name] = make_vec_env(cfg.env, n_envs, seed=0, subproc=subproc)
        try:
            rng = np.random.default_rng(0)
            for _ in range(rounds):
                for name, venv in venvs.items():
                    rates[name].append(_steps_per_second(venv, steps, rng))
                    print(f"{name:48s} {rates[name][-1]:9.1f} env steps/s", flush=True)
        finally:
            for venv in venvs.values():
                venv.close()
    return rates


def encoder_rate(batch: int, repeats: int) -> float:
    """Frames/s of V_s's encoder (the CarRacing architecture, untrained) on one torch thread."""
    from plls_bench.repr.train import new_model

    with tempfile.TemporaryDirectory() as tmp:
        cfg = compose(["+experiment=carracing_vs", "budget=quick", f"runs_dir={tmp}"])
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        model = new_model(cfg, "state").eval()
        x = torch.rand(batch, 3, cfg.env.image_size, cfg.env.image_size)
        with torch.inference_mode():
            model.encode(x)  # warm-up
            start = time.perf_counter()
            for _ in range(repeats):
                model.encode(x)
        return batch * repeats / (time.perf_counter() - start)
    finally:
        torch.set_num_threads(threads)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--envs", type=int, default=16, help="envs in the vector env (Table 2: 16)")
    parser.add_argument("--steps", type=int, default=300, help="vector steps per measurement")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved measurements per setting")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    command = announce("env_speed.py", argv)
    rates = env_rates(args.envs, args.steps, args.rounds)
    encoder = encoder_rate(args.envs, 50)
    print(f"V_s encoder forward: {encoder:.0f} frames/s per thread (batch {args.envs})")
    base = statistics.median(rates[next(iter(SETTINGS))])
    rows = [f"| {name} | {statistics.median(r):,.0f} | {min(r):,.0f} - {max(r):,.0f} | "
            f"**{statistics.median(r) / base:.1f}x** |" for name, r in rates.items()]
    finish_section(
        SECTION, "CarRacing env steps per second, gymnasium vs envpool (`bench/env_speed.py`)", command,
        f"{args.envs} envs, {args.steps} vector steps of uniform random actions per measurement, "
        f"{args.rounds} rounds interleaved across the settings; median and range of the rounds. Ratios "
        "are against gymnasium in one thread, measured in the same run.",
        ["setting", "env steps/s (median)", "range", "ratio"], rows,
        notes=[f"V_s encoder forward, batch {args.envs}, one torch thread: **{encoder:,.0f} frames/s**: the "
               "most a PL-LS or V_s-only rollout can step per thread, however fast the env."],
        write=not args.no_write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
