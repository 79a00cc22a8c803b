"""Run every experiment preset of a profile with all its trials, as Hydra multiruns.

``./reproduce.sh`` bootstraps ``.venv`` and then calls ``python -m plls_bench.reproduce``.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from plls_bench.composition import CONF_DIR, compose
from plls_bench.config import BUDGET_NAMES, ConfigError


@dataclass(frozen=True)
class PlannedPreset:
    experiment: str
    trials: int
    env: str


def list_presets() -> list[str]:
    return sorted(p.stem for p in (CONF_DIR / "experiment").glob("*.yaml"))


def plan(profile: str, only: list[str] | None = None) -> list[PlannedPreset]:
    """The presets of ``profile`` (all, or ``only``) and how many trials each runs."""
    presets = list_presets()
    unknown = sorted(set(only or []) - set(presets))
    if unknown:
        raise ConfigError(f"--only: unknown preset(s) {', '.join(unknown)}; known: {', '.join(presets)}")
    planned = []
    for name in only or presets:
        cfg = compose([f"+experiment={name}", f"budget={profile}"])
        planned.append(PlannedPreset(name, cfg.budget.trials, cfg.env.name))
    return planned


def multirun_command(item: PlannedPreset, profile: str, runs_dir: str) -> list[str]:
    seeds = ",".join(str(k) for k in range(item.trials))
    return [sys.executable, "-m", "plls_bench", "-m", f"+experiment={item.experiment}",
            f"budget={profile}", f"seed={seeds}", f"runs_dir={runs_dir}"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="reproduce.sh", description=__doc__)
    parser.add_argument("--profile", choices=BUDGET_NAMES, default="paper", help="compute profile")
    parser.add_argument("--only", nargs="+", metavar="PRESET", help="run only these presets")
    parser.add_argument("--runs", default="results/runs", help="root of run directories")
    parser.add_argument("--out", default="results", help="where the results collector writes tables and figures")
    parser.add_argument("--no-report", action="store_true", help="run the presets only, not the collector")
    parser.add_argument("--dry-run", action="store_true", help="print the plan, run nothing")
    args = parser.parse_args(argv)
    try:
        planned = plan(args.profile, args.only)
    except ConfigError as err:
        print(f"reproduce: {err}", file=sys.stderr)
        return 2
    for item in planned:
        print(f"{item.experiment:32s} {item.env:12s} trials={item.trials}")
    if args.dry_run:
        return 0
    failed = []
    for item in planned:
        start = time.perf_counter()
        done = subprocess.run(multirun_command(item, args.profile, args.runs))
        status = "ok" if done.returncode == 0 else f"FAILED (exit {done.returncode})"
        print(f"[reproduce] {item.experiment}: {status} in {time.perf_counter() - start:.0f}s", flush=True)
        if done.returncode != 0:
            failed.append(item.experiment)
    report = 0 if args.no_report else collect_results(args.runs, args.out)
    if failed:
        print(f"[reproduce] failed presets: {', '.join(failed)}", file=sys.stderr)
        return 1
    return report


def collect_results(runs_dir: str, out_dir: str) -> int:
    """Regenerate every table and figure from the runs (gaps from failed presets are reported)."""
    from plls_bench.report.__main__ import main as report_main  # lazy: plotting stack

    Path(runs_dir).mkdir(parents=True, exist_ok=True)  # a profile whose presets all failed
    print(f"[reproduce] results collector: {runs_dir} -> {out_dir}", flush=True)
    return report_main(["--runs", runs_dir, "--out", out_dir, "--no-progress"])


if __name__ == "__main__":
    sys.exit(main())
