"""The front page's profile table: what each profile (``conf/budget/``) runs and what it costs, as
the dry run plans it on a fresh clone. Written by the collector into ``README.md`` between its own
markers, beside the headline, so the costs cannot go stale: ``tests/test_front_page.py`` fails when
the committed block differs from what the plan gives.

Only committed inputs are read (``conf/``, ``bench/throughput.json``, ``results/records``, the smoke
timing in ``docs/benchmarks.md``): the plan runs against a runs dir that never exists beside the
checkout's records, and the wall estimate assumes ``--launcher joblib --jobs 2`` (one thread per
trial), not this machine's cores, so regenerating the block anywhere leaves no diff."""
from __future__ import annotations

import re
from pathlib import Path

from plls_bench.pipeline.launch import estimated_wall_seconds
from plls_bench.pipeline.plan import PresetPlan, plan_profile
from plls_bench.pipeline.plan_totals import plan_totals

REPO = Path(__file__).resolve().parents[2]
START = "<!-- profiles: written by `python -m plls_bench.report`; edit plls_bench/report/profile_costs.py, not this -->"
END = "<!-- /profiles -->"
# A fresh clone's runs dir: never made, so only the committed records beside it count as done.
FRESH_RUNS = REPO / "results" / "runs-of-a-fresh-clone"
BENCHMARKS = REPO / "docs" / "benchmarks.md"
SMOKE_SECTION = ("<!-- profile_time:begin -->", "<!-- profile_time:end -->")  # bench/profile_time.py's
SMOKE_ANCHOR = "docs/benchmarks.md#wall-time-of-a-whole-profile-benchprofile_timepy-profilesmoke"
JOBS = 2  # the reference machines' cores (bench/throughput.json): the README's wall estimate
SUMMARY = {"smoke": "every preset at tiny budgets: the whole pipeline",
           "quick": "the paper's settings at reduced budgets",
           "paper": "the paper's budgets and trial counts, or a claims row's planned n where larger"}
NOTES = {"paper": "; a GPU is recommended"}
ENV_TITLES = {"mountaincar": "MountainCar", "carracing": "CarRacing", "cheetah": "cheetah-run"}


def _span(values: list[int]) -> str:
    low, high = min(values), max(values)
    return f"{low:,}" if low == high else f"{low:,}-{high:,}"


def describe(plans: list[PresetPlan]) -> str:
    """Trials and env steps per trial of the policy learners, by env, as the budgets set them."""
    learners: dict[str, list[PresetPlan]] = {}
    for plan in plans:
        if plan.env_steps_per_trial:
            learners.setdefault(plan.env, []).append(plan)
    known = list(ENV_TITLES)
    order = sorted(learners, key=lambda env: (known.index(env) if env in known else len(known), env))
    parts = [f"{ENV_TITLES.get(env, env)} {_span([len(p.trials) for p in learners[env]])} trials x "
             f"{_span([p.env_steps_per_trial for p in learners[env]])} env steps" for env in order]
    return "; ".join(parts)


def smoke_timing(path: Path = BENCHMARKS) -> tuple[float, str, str, int]:
    """(minutes, date, cores, presets timed) of the measured smoke profile in ``docs/benchmarks.md``."""
    text = path.read_text()
    begin, end = (text.index(marker) for marker in SMOKE_SECTION)
    section = text[begin:end]
    minutes = re.search(r"finished in \d+ s \(([\d.]+) min\)", section)
    date = re.search(r"^Measured: (\S+)", section, re.MULTILINE)
    cores = re.search(r"^Machine: .*?(\d+) cores", section, re.MULTILINE)
    if minutes is None or date is None or cores is None:
        raise ValueError(f"{path}: the smoke timing section lacks its 'finished in ... min', 'Measured:' "
                         "or 'Machine: ... cores' line")
    return float(minutes[1]), date[1], cores[1], len(re.findall(r"^\| `", section, re.MULTILINE))


def cost(profile: str, plans: list[PresetPlan]) -> str:
    """A profile's dry-run cost from scratch and on a fresh clone, whose ``plans`` count the committed
    records as done."""
    scratch = plan_totals(plan_profile(profile, str(FRESH_RUNS), count_records=False))
    left = plan_totals(plans)
    wall = estimated_wall_seconds(plans, JOBS, "shortest", "joblib")
    unmeasured = f"; {len(left.missing_rates)} unmeasured rate(s) left out" if left.missing_rates else ""
    return (f"{scratch.seconds / 3600:,.1f} CPU-hours from scratch; {left.seconds / 3600:,.1f} left on a fresh "
            f"clone ({left.pending} of {left.trials} trials; {left.recorded} recorded), about "
            f"{wall / 3600:,.0f} h wall with `--launcher joblib --jobs {JOBS}`{unmeasured}")


def build_profiles() -> str:
    """The block between the markers (markers included)."""
    if FRESH_RUNS.exists():
        raise ValueError(f"{FRESH_RUNS} exists: the profile table plans a fresh clone, whose runs dir is empty")
    smoke = plan_profile("smoke", str(FRESH_RUNS))
    minutes, date, cores, timed = smoke_timing()
    rows = [f"| `smoke` | {SUMMARY['smoke']} ({len({p.experiment for p in smoke})} presets, "
            f"{plan_totals(smoke).trials} trials) | {minutes:g} min wall, measured {date} on a {cores}-core VM "
            f"when there were {timed} presets ([benchmarks]({SMOKE_ANCHOR})) |"]
    for name in ("quick", "paper"):
        plans = plan_profile(name, str(FRESH_RUNS))
        rows.append(f"| `{name}` | {SUMMARY[name]}: {describe(plans)} | {cost(name, plans)}{NOTES.get(name, '')} |")
    return "\n".join([START, "", "| profile | what it runs | estimated cost (dry run, 2-core reference VMs) |",
                      "|---|---|---|", *rows, "", END])
