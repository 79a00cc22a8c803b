"""The report of :mod:`plls_bench.validation.dbc_reference_parity`: the reference agents it can
stand beside a suite preset, its markdown and the reference checkout's commit."""
from __future__ import annotations

import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class ReferenceAgent:
    """One agent of the reference and the suite preset that reimplements it."""

    module: str   # under the checkout's agent/
    name: str     # its class
    preset: str   # the suite's experiment preset; both sides take its algo.dbc settings
    title: str    # what the report calls it
    report: str   # file stem of the report under --out
    bisim: bool   # trains the bisimulation, transition and reward losses (BisimAgent), or the critic alone


def markdown(report: dict[str, Any], agent: ReferenceAgent) -> str:
    """The report as markdown: command, reference commit, machine, data, verdict and one table of
    per-network differences per dtype."""
    m = report["machine"]
    files = ", ".join(f"`{f}`" for f in (f"agent/{agent.module}.py", "sac_ae.py", "encoder.py", "transition_model.py"))
    lines = [f"# {agent.title}: the suite's update beside the reference's", "",
             f"Command: `{report['command']}`  ",
             f"Reference: facebookresearch/deep_bisim4control at `{report['reference_commit']}`, imported from its "
             f"checkout ({files})  ",
             f"Machine: {m['cpu']}, {m['cores']} cores, torch {m['torch']}; load average {m['load']}.  ",
             f"Data: {report['steps']} uniform-random agent steps of `{agent.preset}` (pixels, budget=quick), "
             f"minibatches of {report['batch']}; updates at agent steps 1..{report['updates']} (actor, temperature "
             "and targets on even steps). Gaussian noise zero"
             + (" and one bisimulation pairing" if agent.bisim else "") + " in both: the two codes "
             "draw them in different calls (`plls_bench/validation/dbc_reference_parity.py` says why and how to read "
             "the tables).",
             "", f"**Verdict:** {report['verdict']}", ""]
    for name, rows in report["dtypes"].items():
        networks = list(rows[0]["max_difference"])
        lines += [f"## {name}", "", "| update | latent spread, suite | latent spread, reference | "
                  + " | ".join(f"max diff {n}" for n in networks) + " |", "|---" * (3 + len(networks)) + "|"]
        lines += [f"| {r['update']} | {r['suite_spread']:.4g} | {r['reference_spread']:.4g} | "
                  + " | ".join(f"{r['max_difference'][n]:.2g}" for n in networks) + " |" for r in rows]
        lines.append("")
    return "\n".join(lines)


def reference_commit(path: Path) -> str:
    """The checkout's HEAD, or why there is none."""
    done = subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 else "unknown (not a git checkout)"
