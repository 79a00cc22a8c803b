"""Film a run's policy: ``python -m plls_bench.film RUN_DIR [--out DIR] [--device D] [KEY=VALUE ...]``.

The recording is :mod:`plls_bench.film.recording`'s (Figs 11, 19, 22). This command sits above
the runner registry: it looks up the run's runner and hands the filmstrip that runner's policy
loader, so the recording itself never imports the registry. ``reproduce`` runs it for the first
trial of every filmed preset.

Layer ``entry points`` of tests/test_imports.py: imports only from itself and the layers below it
(``core`` up to ``report``); no layer below imports it.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from plls_bench.config import ConfigError
from plls_bench.core.atomic_files import read_json
from plls_bench.film import recording as filmstrip
from plls_bench.pipeline.runner_registry import RUNNERS, filming_runners
from plls_bench.rundirs.devices import require_device
from plls_bench.train.trained_policy import PolicyLoader


def policy_loader(run_dir: Path, runner: str | None) -> PolicyLoader:
    """How the run's runner spec loads its policy; ConfigError for a runner without one."""
    spec = RUNNERS.get(runner or "")
    if spec is None or spec.load_policy is None:
        raise ConfigError(f"{run_dir}: runner {runner!r} has no policy to film; filmstrips exist for "
                          f"{', '.join(filming_runners())}")
    return spec.load_policy()


def film_run(run_dir: Path, out: Path | None = None, overrides: list[str] | None = None,
             device: str = "auto", max_steps: int = 0) -> dict:
    """Record ``run_dir``'s policy with its runner's loader; returns filmstrip.json's content."""
    record_json = read_json(run_dir / "config.json")
    if record_json is None:
        raise ConfigError(f"{run_dir}: no readable config.json, not a run directory")
    load = policy_loader(run_dir, record_json["config"].get("runner"))
    return filmstrip.make_filmstrip(run_dir, load, out, overrides, device, max_steps)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m plls_bench.film", description=filmstrip.__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path, help="a ppo (or dbc) run directory with a checkpoint")
    parser.add_argument("--out", type=Path, help="where frames.npz and filmstrip.json go (RUN_DIR/filmstrip)")
    parser.add_argument("--device", default="auto", help="torch device of the policy: cpu | cuda | auto "
                        "(cuda when present); any device, whatever the run trained on")
    parser.add_argument("--max-steps", type=int, default=0, help="cap the episode at this many agent steps")
    parser.add_argument("overrides", nargs="*", metavar="KEY=VALUE",
                        help="filmstrip settings, e.g. interval=8 episode=2 (conf/filmstrip/<env>.yaml)")
    args = parser.parse_intermixed_args(argv)  # KEY=VALUE before or after the options
    try:
        if not args.run_dir.is_dir():
            raise ConfigError(f"{args.run_dir}: no such run directory")
        require_device(args.device, "--device")
        meta = film_run(args.run_dir, args.out, args.overrides, args.device, args.max_steps)
    except (ConfigError, FileNotFoundError) as err:
        print(f"filmstrip: {err}", file=sys.stderr)
        return 2
    goal = f", goal after {meta['steps_to_goal']} steps" if meta["steps_to_goal"] is not None else ""
    print(f"filmstrip: {len(meta['frame_steps'])} frames every {meta['interval']} steps, "
          f"return {meta['episode_return']:.2f}, {meta['episode_length']} steps{goal} "
          f"-> {args.out or args.run_dir / 'filmstrip'}")
    return 0
