"""The rate table the dry run's cost estimates read: the keys a trial's work is priced by
(:func:`rate_keys`, the one place they are built, with their tags from :func:`rate_suffix`) and the
throughputs ``bench/throughput.py`` measured for them (``bench/throughput.json``, on a reference
machine: :func:`rate_machines` says which)."""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from plls_bench.config import Config
from plls_bench.pipeline.runner_registry import runner_spec
from plls_bench.rundirs.composition import CONF_DIR
from plls_bench.rundirs.run_dir import backend_tag

THROUGHPUT_FILE = CONF_DIR.parent / "bench" / "throughput.json"


def load_rates(path: Path = THROUGHPUT_FILE) -> dict[str, float]:
    """Measured throughputs by key (``collect/<env>``, ``repr_<which>/<env>``, ``train/<preset>``,
    ``eval/<preset>``, ``study/<preset>``); empty when never measured."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return {key: float(entry["value"]) for key, entry in data.get("rates", {}).items()}


def rate_machines(path: Path = THROUGHPUT_FILE) -> dict[str, int]:
    """How many measured rates each CPU gave, by the CPU's name in the rate's ``machine`` field
    (``vm: x86_64, <CPU>, 2 cores, load ...``; "an unnamed CPU" for rates measured before the
    name was written), most rates first."""
    try:
        entries = json.loads(path.read_text()).get("rates", {}).values()
    except (OSError, ValueError):
        return {}
    names: Counter[str] = Counter()
    for entry in entries:
        parts = [part.strip() for part in str(entry.get("machine", "")).split(",")]
        named = len(parts) > 2 and not parts[1].endswith("cores")
        names[parts[1] if named else "an unnamed CPU"] += 1
    return dict(names.most_common())


def rate_keys(cfg: Config) -> dict[str, str]:
    """Every rate key a trial of ``cfg`` can be costed with, by the work it prices: ``collect`` (its
    dataset), ``repr_state`` / ``repr_action`` (its V_s / V_a), ``train`` and ``eval`` (policy
    learning and its evaluations), ``run`` (a fixed cost per run). The one place rate keys are
    built: the plan's costs and ``bench/throughput.py``'s measurements both read them here."""
    spec, env, preset = runner_spec(cfg.runner), cfg.env.name, cfg.experiment
    models = [which for which in ("state", "action") if getattr(cfg.repr, which).kind == "vae"]
    keys = {}
    if spec.uses_dataset or models:
        keys["collect"] = f"collect/{env}{rate_suffix(cfg, precision_bound=False)}"
    for which in models:  # only V_s has conv trunks: V_a's rate does not depend on the precision
        keys[f"repr_{which}"] = f"repr_{which}/{env}{rate_suffix(cfg, False, which == 'state')}"
    if spec.trains_policy:
        keys.update(train=f"train/{preset}{rate_suffix(cfg)}", eval=f"eval/{preset}{rate_suffix(cfg)}")
    if spec.costs_per_run:
        keys["run"] = f"{spec.name}/{preset}"
    return keys


def rate_suffix(cfg: Config, env_bound: bool = True, precision_bound: bool = True) -> str:
    """The one place rate keys get their tags: ``@<backend>`` for env-bound work (collection,
    training, evaluation) off gymnasium, then ``@<precision>`` for work through conv trunks off
    fp32 (fp32 keeps the bare keys measured before ``precision`` existed):
    ``train/carracing_ppo@envpool@bf16``. A bf16 run with no bf16 rate is a missing rate."""
    tags = [cfg.env.backend] if env_bound and backend_tag(cfg.env.backend) else []
    tags += [cfg.precision] if precision_bound and cfg.precision != "fp32" else []
    return "".join(f"@{tag}" for tag in tags)
