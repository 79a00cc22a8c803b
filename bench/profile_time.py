"""Wall time of a whole profile: ``reproduce --profile NAME`` from empty run and result dirs.

    nice -n 10 .venv/bin/python bench/profile_time.py                    # smoke (a few minutes)
    nice -n 10 .venv/bin/python bench/profile_time.py --profile quick --only 'mountaincar_*'   # ~1.5-2 h

Runs the main job exactly as ``./reproduce.sh`` does (every preset's pending trials as Hydra
multiruns, the filmstrips, the results collector) into a temporary directory, prints its output,
and rewrites this script's section of ``docs/benchmarks.md`` with the total and each preset's time.
The ``.venv`` set-up is not included (``reproduce.sh`` reuses it once made).
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bench.benchmarks_md import announce, machine, write_section  # noqa: E402

SECTION = "profile_time"
PRESET_LINE = re.compile(r"^\[reproduce\] (\S+): (.*), (\d+)s$")


def run_profile(profile: str, only: list[str] | None, root: Path) -> tuple[int, float, str]:
    """Exit status, wall seconds and combined output of one reproduce run under ``root``."""
    command = [sys.executable, "-m", "plls_bench.reproduce", "--profile", profile,
               "--runs", str(root / "runs"), "--out", str(root / "results"), *(["--only", *only] if only else [])]
    start = time.perf_counter()
    done = subprocess.run(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    return done.returncode, time.perf_counter() - start, done.stdout


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", default="smoke", help="budget profile (smoke, quick, paper)")
    parser.add_argument("--only", nargs="+", metavar="PRESET", help="time only these presets")
    parser.add_argument("--no-write", action="store_true", help="print only, leave docs/benchmarks.md alone")
    args = parser.parse_args(argv)
    command = announce("profile_time.py", argv)
    with tempfile.TemporaryDirectory(prefix="plls_profile_") as tmp:
        status, seconds, output = run_profile(args.profile, args.only, Path(tmp))
    print(output)
    after = machine()
    rows = [f"| `{m[1]}` | {m[2]} | {m[3]} |" for m in map(PRESET_LINE.match, output.splitlines()) if m]
    verdict = "finished" if status == 0 else f"FAILED (exit {status})"
    print(f"profile {args.profile}: {verdict} in {seconds:.0f} s\nmachine (after): {after}")
    text = "\n".join([
        f"## Wall time of a whole profile (`bench/profile_time.py`, profile={args.profile})", "",
        f"Command: `{command}`  ", f"Machine: {after}  ", f"Measured: {date.today().isoformat()}  ",
        f"**{verdict} in {seconds:.0f} s ({seconds / 60:.1f} min)**: every preset's trials, the filmstrips "
        "and the results collector, from empty run and result dirs (the `.venv` already made). "
        "Per preset (process start, compute, evaluation):", "",
        "| preset | outcome | seconds |", "|---|---|---|", *rows])
    if not args.no_write:  # one section per profile and selection, so a quick run keeps the smoke row
        write_section(SECTION if args.profile == "smoke" and not args.only else f"{SECTION}_{args.profile}", text)
    return status


if __name__ == "__main__":
    sys.exit(main())
