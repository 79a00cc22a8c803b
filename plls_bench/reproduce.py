"""Run every experiment preset of a profile with all its trials as Hydra multiruns, then the
results collector. ``./reproduce.sh`` bootstraps ``.venv`` and calls ``python -m plls_bench.reproduce``.

Trials whose run dir is already done with the same config are not launched again, so an
interrupted reproduce.sh re-run finishes only the rest; an interrupted trial resumes from its
checkpoint. Trials a committed record holds done (``results/records``) count as done too
(``--rerun-recorded`` runs them again), so a fresh clone runs only what is missing. Trials run
as Hydra multiruns (``plls_bench.pipeline.launch``): on this machine one per trial, ``--jobs`` at a time
with ``--launcher joblib``; on SLURM one per preset, through submitit. ``--override KEY=VALUE`` runs
an ablation: a variant of each preset run, beside its own runs (``plls_bench.pipeline.overrides``).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from plls_bench.config import BUDGET_NAMES, PRECISIONS, ConfigError
from plls_bench.config.checks import check_writable_dir
from plls_bench.core.signals import TERMINATED_EXIT_CODE, Terminated, sigterm_raises
from plls_bench.pipeline.filming import film_policies
from plls_bench.pipeline.launch import (
    QUEUE_ORDERS,
    deadline_outlook,
    estimated_wall_seconds,
    launcher_overrides,
    run_plans,
    trial_threads,
)
from plls_bench.pipeline.overrides import override_variants
from plls_bench.pipeline.plan import PresetPlan, plan_profile, plan_sweep
from plls_bench.pipeline.plan_totals import plan_totals
from plls_bench.pipeline.rates import THROUGHPUT_FILE, rate_machines
from plls_bench.pipeline.sweeps import load_sweep, sweep_names
from plls_bench.rundirs.devices import cpu_model
from plls_bench.rundirs.record_layout import records_dir_for

LAUNCHERS = ("local", "joblib", "slurm")
# Smoke numbers check the pipeline, not the paper: the committed results/ is written only from
# records or runs of a real profile, and a smoke run's collector writes a git-ignored folder.
RESULTS_OUT, SMOKE_OUT = "results", "results/smoke"
DEFAULT_RUNS = "results/runs"
EXIT_INTERRUPTED = 130


def format_plan(plans: list[PresetPlan], jobs: int, stop_after_min: float = 0.0, order: str = "shortest",
                launcher: str = "joblib") -> str:
    """The plan as a table, with estimated compute from measured throughput, and what a
    ``--stop-after-min`` deadline leaves of it under ``launcher``."""
    width = max([28, *(len(p.label) for p in plans)])
    rows = [f"{'preset':{width}s} {'runner':8s} {'to run':>9s} {'recorded':>8s} {'env steps/trial':>15s} "
            f"{'est. CPU-h':>10s}"]
    for p in plans:
        est = "n/a" if p.seconds is None else f"{p.seconds / 3600:.2f}"
        trials = f"{len(p.pending)}/{len(p.trials)}"
        rows.append(f"{p.label:{width}s} {p.runner:8s} {trials:>9s} {p.recorded:>8d} {p.env_steps_per_trial:>15,d} "
                    f"{est:>10s}")
    for p in plans:  # trials that continue from a checkpoint: only their remainder is costed
        rows += [f"  resumes: {p.label} seed={t.seed} at iteration {t.resumes_at:,}/{t.iterations:,} "
                 f"(from its {t.resumes_from})" for t in p.pending if t.resumes_from]
        rows += [f"  behind: {p.label} seed={t.seed} at iteration {t.resumes_at:,}/{t.iterations:,}; "
                 f"an earlier attempt reached {t.lost_at:,} (its pending record: metrics only, no checkpoint)"
                 for t in p.pending if t.lost_at]
        if p.inert:  # planned all the same: the override is the user's, the warning only says it is inert
            rows.append(f"  warning: {p.label}: {', '.join(p.inert)}: no module of this preset reads it, so "
                        "its trials compute what the preset's own do")
    totals = plan_totals(plans)
    rerun = "run again (--rerun-recorded)" if plans and not plans[0].count_records else "counted as done"
    rows.append(f"trials to run: {totals.pending} of {totals.trials} (the rest are done); "
                f"{totals.recorded} recorded in committed records, {rerun}")
    threads = max((trial_threads(p, t, launcher) for p in plans for t in p.pending), default=1)
    rows.append(f"estimated compute: {totals.seconds / 3600:.1f} CPU-hours (one trial per process); "
                f"about {estimated_wall_seconds(plans, jobs, order, launcher) / 3600:.1f} h wall with {jobs} "
                f"parallel job(s) of up to {threads} thread(s) each, trials started in the launch queue's order "
                f"({order} estimated time left first)")
    if stop_after_min > 0:
        rows += deadline_outlook(plans, jobs, stop_after_min, order, launcher)
    if totals.missing_rates:
        rows.append(f"no measured throughput for {', '.join(totals.missing_rates)}: left out of the estimate "
                    f"(bench/throughput.py measures them into {THROUGHPUT_FILE.name})")
    machines = rate_machines()
    if machines:  # rates move with the CPU (CNN training 2x between two 2-core VMs: docs/benchmarks.md)
        rows.append(f"rates measured on {', '.join(f'{cpu} ({n})' for cpu, n in machines.items())}; "
                    f"this machine: {cpu_model()}, {os.cpu_count()} cores")
    return "\n".join(rows)


def export_run_records(runs_dir: str) -> None:
    """Copy the small files of every finished non-smoke run into the committed records folder
    beside the runs dir, so the evidence survives a fresh clone (commit them with git)."""
    from plls_bench.pipeline.record_export import export_records

    done = export_records(runs_dir)
    print(f"[reproduce] records: {done.summary()} under {records_dir_for(runs_dir)} "
          f"(commit them to keep this evidence)", flush=True)
    for line in done.held:
        print(f"[reproduce] records: held {line}", flush=True)
    for line in done.skipped:
        print(f"[reproduce] records: skipped {line}", flush=True)


def collect_results(runs_dir: str, out_dir: str) -> int:
    """Regenerate every table and figure from the runs (gaps from failed presets are reported).
    A command of its own: the launcher does not import the report package."""
    Path(runs_dir).mkdir(parents=True, exist_ok=True)  # a profile whose presets all failed
    print(f"[reproduce] results collector: {runs_dir} -> {out_dir}", flush=True)
    command = [sys.executable, "-m", "plls_bench.report", "--runs", runs_dir, "--out", out_dir, "--no-progress"]
    return subprocess.run(command).returncode


def records_line(runs_dir: str) -> str:
    """Which committed records a launch counts: those beside ``--runs`` only (``records_dir_for``),
    so a runs dir elsewhere (a cluster's scratch) is told when the checkout's records go unread."""
    records, checkout = records_dir_for(runs_dir), records_dir_for(DEFAULT_RUNS)
    if records.is_dir():
        return f"[reproduce] records: {records} (trials and V_s / V_a recorded there count as done)"
    line = f"[reproduce] records: none at {records}, so every pending trial and V_s / V_a is built anew"
    if checkout.is_dir() and checkout.resolve() != records.resolve():
        line += (f"; the records under {checkout} are not read (records are read beside --runs): "
                 f"`ln -s {checkout.resolve()} {records}` counts them")
    return line


def build_parser() -> argparse.ArgumentParser:
    """``reproduce.sh``'s options (checked together by ``parse_args``)."""
    parser = argparse.ArgumentParser(prog="reproduce.sh", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", choices=BUDGET_NAMES, default="paper", help="compute profile (default: paper)")
    parser.add_argument("--launcher", choices=LAUNCHERS, default="local",
                        help="local: one trial at a time; joblib: --jobs trials at a time, the next pending trial "
                             "of any preset starting as soon as one ends; slurm: submitit")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel trials with --launcher joblib")
    parser.add_argument("--queue-order", choices=QUEUE_ORDERS, default="shortest",
                        help="which pending trial the queue starts next (local, joblib): the least estimated "
                             "time left (default: trials end, and are recorded, soonest) or the longest (the "
                             "queue as a whole ends soonest: for a campaign whose verdict needs every trial)")
    parser.add_argument("--hydra", action="append", default=[], metavar="KEY=VALUE",
                        help="extra launcher setting, e.g. --hydra hydra.launcher.partition=cpu (repeatable)")
    parser.add_argument("--override", action="append", default=[], metavar="KEY=VALUE",
                        help="an ablation of every preset run, in a variant dir beside its own runs (which run too), "
                             "e.g. repr.action.latent_dim=8 (repeatable: one variant; KEY=V1,V2: one per value)")
    parser.add_argument("--only", nargs="+", metavar="PRESET",
                        help="run only these presets (names or globs, e.g. 'mountaincar_*')")
    parser.add_argument("--sweep", metavar="NAME",
                        help="run a declared sweep instead of whole presets "
                             f"(conf/sweep/<name>.yaml: {', '.join(sweep_names())}): "
                             "its preset's own runs and one variant per other value")
    parser.add_argument("--precision", choices=PRECISIONS, default="fp32",
                        help="conv trunks' precision for every preset (default fp32, every preset's own): "
                             "bf16 adds precision=bf16 to each run (its run dir variant) and costs it "
                             "with bf16 rates")
    parser.add_argument("--time-limit-min", type=float, default=0.0, metavar="MIN",
                        help="per trial: a learner stops at its last checkpoint before MIN minutes (status "
                             "stopped) and the next launch resumes it; for job time limits (default 0: none)")
    parser.add_argument("--stop-after-min", type=float, default=0.0, metavar="MIN",
                        help="the whole launch on this machine: no trial starts after MIN minutes (nor one "
                             "estimated to reach its first checkpoint, or its end, later), and each "
                             "gets the time left as its time limit when it starts, so learners stop at a "
                             "checkpoint by then (status stopped; the next launch resumes them); for a "
                             "sitting of known length (default 0: none; not with --launcher slurm)")
    parser.add_argument("--runs", default=DEFAULT_RUNS, help="root of run directories; the committed records "
                        "read and written are those beside it (results/runs -> results/records)")
    parser.add_argument("--out", default=None,
                        help=f"where the results collector writes tables and figures (default: {SMOKE_OUT} for "
                             f"--profile smoke, git-ignored; else {RESULTS_OUT}, the committed results)")
    parser.add_argument("--no-report", action="store_true",
                        help="run the presets (and, but for --profile smoke, export their records into "
                             "the records folder beside --runs), not the results collector")
    parser.add_argument("--dry-run", action="store_true", help="print the plan and its estimated cost, run nothing")
    parser.add_argument("--rerun-recorded", action="store_true",
                        help="run trials that a committed record holds done again (default: counted as done)")
    return parser


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The options, with every bad value or combination refused by one ``parser.error`` naming it."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.jobs < 1:
        parser.error(f"--jobs must be >= 1, got {args.jobs}")
    for option, minutes in (("--time-limit-min", args.time_limit_min), ("--stop-after-min", args.stop_after_min)):
        if not minutes >= 0:
            parser.error(f"{option} must be >= 0, got {minutes:g}")
    if args.stop_after_min > 0 and args.launcher == "slurm":
        parser.error("--stop-after-min: SLURM starts jobs when it chooses; give each a limit with --time-limit-min")
    if args.sweep and args.only:
        parser.error("--sweep and --only: give one (a sweep runs only its own preset)")
    if args.sweep and args.override:
        parser.error("--sweep and --override: give one (a sweep declares its own overrides)")
    bad = [h for h in args.hydra if not h.startswith("hydra.") or "=" not in h]
    if bad:
        parser.error(f"--hydra takes hydra.* KEY=VALUE settings (a config key goes to --override KEY=VALUE), "
                     f"got {', '.join(bad)}")
    try:
        args.variants = override_variants(args.override)
    except ConfigError as err:
        parser.error(str(err))
    if args.out is None:
        args.out = SMOKE_OUT if args.profile == "smoke" else RESULTS_OUT
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        check_writable_dir(args.runs, "--runs")  # before any launch: a job could not even log its failure
        if not args.no_report:
            check_writable_dir(args.out, "--out")
        count_records = not args.rerun_recorded
        # fp32 adds nothing: the presets' own value, so their run dirs stay where they are
        extra = (f"precision={args.precision}",) if args.precision != "fp32" else ()
        if args.sweep:
            plans = plan_sweep(load_sweep(args.sweep), args.profile, args.runs, count_records=count_records,
                               overrides=extra)
        else:
            plans = plan_profile(args.profile, args.runs, args.only, count_records=count_records, overrides=extra,
                                 variants=args.variants)
    except ConfigError as err:
        print(f"reproduce: {err}", file=sys.stderr)
        return 2
    jobs = args.jobs if args.launcher == "joblib" else 1
    print(f"[reproduce] profile={args.profile} launcher={args.launcher} runs={args.runs}")
    print(records_line(args.runs))
    print(format_plan(plans, jobs, args.stop_after_min, args.queue_order, args.launcher), flush=True)
    if args.dry_run:
        return 0
    overrides = launcher_overrides(args.launcher, args.hydra)
    try:
        with sigterm_raises():  # SIGTERM to reproduce alone reaches the trials it started (launch.run_queue)
            failed = run_plans(plans, args.profile, args.runs, overrides, jobs=jobs,
                               per_trial=args.launcher != "slurm", time_limit_min=args.time_limit_min,
                               stop_after_min=args.stop_after_min, order=args.queue_order,
                               launcher=args.launcher)
            failed += film_policies(plans)
    except KeyboardInterrupt:
        print("\n[reproduce] interrupted: finished runs are kept and an interrupted trial resumes "
              "from its checkpoint; run the same command again to finish the rest", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated as stop:
        print(f"[reproduce] {stop}: the running trials were stopped (status stopped) and resume from "
              "their checkpoints; run the same command again to finish the rest", file=sys.stderr)
        return TERMINATED_EXIT_CODE
    if args.profile != "smoke":
        export_run_records(args.runs)
    report = 0 if args.no_report else collect_results(args.runs, args.out)
    if failed:
        print(f"[reproduce] failed presets: {', '.join(failed)} (see their status.json and run.log)", file=sys.stderr)
        return 1
    return report


if __name__ == "__main__":
    sys.exit(main())
