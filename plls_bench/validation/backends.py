"""Do gymnasium's and envpool's CarRacing pose the same task? Four measurements, one report.

``python -m plls_bench.validation.backends [--episodes 30] [--runs results/runs] [--policy RUN_DIR]``

1. Random-policy returns and episode lengths over ``--episodes`` tracks per backend (the suite's
   data policy, full 1000-step episodes): means with 95% CIs, Welch's t-test, Mann-Whitney U and
   Kolmogorov-Smirnov two-sample tests.
2. Per-channel frame statistics (mean, std of R, G, B in [0, 1]) over every frame of (1).
3. V_s trained on one backend's frames (the profile's V_s, loaded, never trained here) reconstructs
   the frames of (1) from each backend: the MSE ratio other / own must be within 1.10.
4. A trained PL-LS policy (``--policy``, a ``carracing_plls_ppo`` run dir) on 10 tracks of each
   backend: mean returns with CIs, Welch's t-test.

The tracks differ between backends for the same seed (two random generators), so every comparison
is between distributions, never frame by frame. Writes ``results/analysis/backend_validation.{json,md}``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

from plls_bench.config import Config
from plls_bench.core.atomic_files import atomic_write_bytes, atomic_write_json
from plls_bench.rundirs.composition import compose

BACKENDS = ("gymnasium", "envpool")
VALIDATION_SEED = 20261123  # tracks no dataset of the suite is collected on (data seeds derive from data_seed)


def mean_ci(x: np.ndarray) -> dict[str, float]:
    """Mean and 95% t-interval of samples ``x`` ``(n,)``."""
    x = np.asarray(x, dtype=np.float64)
    half = stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)) if len(x) > 1 else np.nan
    return {"mean": float(x.mean()), "std": float(x.std(ddof=1)) if len(x) > 1 else 0.0,
            "ci_low": float(x.mean() - half), "ci_high": float(x.mean() + half), "n": int(len(x))}


def two_sample(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Tests of ``a`` ``(n,)`` vs ``b`` ``(m,)``: Welch's t (with the 95% CI of mean(b) - mean(a)),
    Mann-Whitney U and Kolmogorov-Smirnov p-values."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if np.ptp(np.concatenate([a, b])) == 0:  # identical constants (e.g. every episode 1000 steps)
        return {"diff": 0.0, "diff_ci_low": 0.0, "diff_ci_high": 0.0, "welch_p": 1.0, "mannwhitney_p": 1.0, "ks_p": 1.0}
    welch = stats.ttest_ind(b, a, equal_var=False)
    ci = welch.confidence_interval(0.95)
    return {"diff": float(b.mean() - a.mean()), "diff_ci_low": float(ci.low), "diff_ci_high": float(ci.high),
            "welch_p": float(welch.pvalue), "mannwhitney_p": float(stats.mannwhitneyu(a, b).pvalue),
            "ks_p": float(stats.ks_2samp(a, b).pvalue)}


def episode_table(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Returns ``(E,)`` and lengths ``(E,)`` of the episodes in collected ``arrays``."""
    returns = np.bincount(arrays["episode"], weights=arrays["rewards"])
    lengths = np.bincount(arrays["episode"])
    return returns, lengths


def channel_stats(frames: np.ndarray) -> dict[str, list[float]]:
    """Per-channel mean and std of uint8 frames ``(N, 3, H, W)``, in [0, 1]."""
    x = frames.astype(np.float64) / 255.0
    return {"mean": x.mean(axis=(0, 2, 3)).tolist(), "std": x.std(axis=(0, 2, 3)).tolist()}


def _config(backend: str, runs: str, budget: str) -> Config:
    return compose(["+experiment=carracing_vs", f"budget={budget}", f"runs_dir={runs}", "progress=false",
                    f"env.backend={backend}"])


def random_policy(episodes: int, steps: int, runs: str, budget: str) -> dict[str, dict[str, np.ndarray]]:
    """The data policy's episodes on each backend (same episode seeds, different tracks)."""
    from plls_bench.data.collect import collect_random_policy

    out = {}
    for backend in BACKENDS:
        cfg = _config(backend, runs, budget)
        print(f"[validation] {episodes} random-policy episodes on {backend}", flush=True)
        out[backend] = collect_random_policy(cfg.env, episodes, steps, VALIDATION_SEED, progress=False)
    return out


def reconstruction(data: dict[str, dict[str, np.ndarray]], runs: str, budget: str, trained_on: str) -> dict[str, Any]:
    """Posterior-mean reconstruction MSE of the profile's V_s (trained on ``trained_on`` frames)
    on each backend's frames of (1)."""
    from plls_bench.repr.fit import Split, mean_reconstruction_mse
    from plls_bench.repr.store import load_representations
    from plls_bench.rundirs.devices import resolve_device

    cfg = _config(trained_on, runs, budget)
    model = load_representations(cfg).state_vae  # never trains: a missing V_s names its preset
    assert model is not None
    mse = {}
    for backend, arrays in data.items():
        frames = arrays["observations"]
        mse[backend] = mean_reconstruction_mse(model, Split(frames, np.arange(len(frames))), 256,
                                               resolve_device("cpu"))
    other = [b for b in BACKENDS if b != trained_on][0]
    return {"trained_on": trained_on, "mse": mse, "ratio_other_to_own": mse[other] / mse[trained_on]}


def policy_returns(run_dir: Path, episodes: int) -> dict[str, Any]:
    """A trained PPO policy's deterministic returns on ``episodes`` tracks of each backend."""
    from plls_bench.envs.evaluation import run_episodes
    from plls_bench.train.ppo_model import build_vec_env, load_trained

    trained = load_trained(run_dir, device="cpu")
    out: dict[str, Any] = {"run": str(run_dir)}
    for backend in BACKENDS:
        cfg = dataclasses.replace(trained.cfg, env=dataclasses.replace(trained.cfg.env, backend=backend), device="cpu")
        venv = build_vec_env(cfg, min(episodes, 10), 0, trained.reprs)
        try:
            result = run_episodes(venv, lambda obs: trained.act(obs), episodes, VALIDATION_SEED)
        finally:
            venv.close()
        out[backend] = result.returns
    out["tests"] = two_sample(np.array(out["gymnasium"]), np.array(out["envpool"]))
    return out


def summarise(data: dict[str, dict[str, np.ndarray]]) -> dict[str, Any]:
    """Measurements (1) and (2) from the collected episodes of both backends."""
    table = {b: episode_table(data[b]) for b in BACKENDS}
    return {
        "returns": {b: mean_ci(table[b][0]) for b in BACKENDS},
        "lengths": {b: mean_ci(table[b][1]) for b in BACKENDS},
        "returns_test": two_sample(table["gymnasium"][0], table["envpool"][0]),
        "lengths_test": two_sample(table["gymnasium"][1], table["envpool"][1]),
        "channels": {b: channel_stats(data[b]["observations"]) for b in BACKENDS},
        "per_episode_returns": {b: table[b][0].tolist() for b in BACKENDS},
    }


def _ci(m: dict[str, float]) -> str:
    return f"{m['mean']:.1f} [{m['ci_low']:.1f}, {m['ci_high']:.1f}] (n={m['n']})"


def _test(t: dict[str, float]) -> str:
    return (f"envpool - gymnasium = {t['diff']:+.1f} [{t['diff_ci_low']:+.1f}, {t['diff_ci_high']:+.1f}]; "
            f"Welch p = {t['welch_p']:.3f}, Mann-Whitney p = {t['mannwhitney_p']:.3f}, KS p = {t['ks_p']:.3f}")


def markdown(report: dict[str, Any]) -> str:
    """The report as markdown: numbers first, verdicts as the tests give them."""
    s = report["summary"]
    lines = ["# CarRacing: gymnasium vs envpool", "", f"Command: `{report['command']}`  ",
             f"Episodes per backend: {report['episodes']} x {report['steps']} steps, the suite's data policy "
             f"(`env.data_policy`), episode seeds from {VALIDATION_SEED}.", "",
             "## 1. Random-policy returns and episode lengths (mean [95% CI])", "",
             "| | gymnasium | envpool | two-sample tests |", "|---|---|---|---|",
             f"| return | {_ci(s['returns']['gymnasium'])} | {_ci(s['returns']['envpool'])} | "
             f"{_test(s['returns_test'])} |",
             f"| length | {_ci(s['lengths']['gymnasium'])} | {_ci(s['lengths']['envpool'])} | "
             f"{_test(s['lengths_test'])} |",
             "", "## 2. Frame statistics per channel (R, G, B in [0, 1])", "",
             "| | mean R, G, B | std R, G, B |", "|---|---|---|"]
    for b in BACKENDS:
        c = s["channels"][b]
        means, stds = (", ".join(f"{v:.4f}" for v in c[k]) for k in ("mean", "std"))
        lines.append(f"| {b} | {means} | {stds} |")
    lines += ["", "## 3. V_s reconstruction across backends", ""]
    rec = report.get("reconstruction")
    if isinstance(rec, dict):
        verdict = "within" if rec["ratio_other_to_own"] <= 1.10 else "NOT within"
        lines += [f"V_s trained on {rec['trained_on']} frames: MSE " +
                  ", ".join(f"{b} {v:.5f}" for b, v in rec["mse"].items()) +
                  f"; other / own = **{rec['ratio_other_to_own']:.3f}** ({verdict} the 10% bound)."]
    else:
        lines.append(f"Not measured: {rec}")
    lines += ["", "## 4. A trained PL-LS policy on both backends", ""]
    pol = report.get("policy")
    if isinstance(pol, dict):
        lines += [f"Run `{pol['run']}`, deterministic actions, {len(pol['gymnasium'])} tracks each: "
                  f"gymnasium {_ci(mean_ci(np.array(pol['gymnasium'])))}, "
                  f"envpool {_ci(mean_ci(np.array(pol['envpool'])))}; "
                  f"{_test(pol['tests'])}."]
    else:
        lines.append(f"Not measured: {pol}")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=30, help="random-policy tracks per backend")
    parser.add_argument("--steps", type=int, default=1000, help="steps per episode (CarRacing: 1000)")
    parser.add_argument("--budget", default="quick", help="profile whose V_s is loaded")
    parser.add_argument("--runs", default="results/runs", help="runs_dir holding the V_s artifact")
    parser.add_argument("--vs-backend", default="envpool", choices=BACKENDS, help="frames V_s was trained on")
    parser.add_argument("--policy", type=Path, default=None, help="a carracing_plls_ppo run dir")
    parser.add_argument("--policy-episodes", type=int, default=10)
    parser.add_argument("--out", type=Path, default=Path("results/analysis"))
    args = parser.parse_args(argv)
    data = random_policy(args.episodes, args.steps, args.runs, args.budget)
    report: dict[str, Any] = {"command": "python -m plls_bench.validation.backends " + " ".join(
        sys.argv[1:] if argv is None else argv), "episodes": args.episodes, "steps": args.steps,
        "summary": summarise(data)}
    try:
        report["reconstruction"] = reconstruction(data, args.runs, args.budget, args.vs_backend)
    except FileNotFoundError as err:
        report["reconstruction"] = str(err)
    report["policy"] = (policy_returns(args.policy, args.policy_episodes) if args.policy
                        else "no --policy run given")
    args.out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(args.out / "backend_validation.json", report)
    atomic_write_bytes(args.out / "backend_validation.md", markdown(report).encode())
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
