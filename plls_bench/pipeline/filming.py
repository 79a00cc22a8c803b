"""The filming step of ``reproduce``: films one done trial of each filmed preset (Figs. 11, 19, 22)
with ``python -m plls_bench.film``, once per run and filmstrip settings."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from plls_bench.config import ENV_NAMES, FilmstripConfig
from plls_bench.config.studies_film import filmstrip_hash
from plls_bench.core.atomic_files import read_json
from plls_bench.pipeline.plan import PresetPlan, Trial
from plls_bench.pipeline.runner_registry import runner_spec
from plls_bench.rundirs.composition import CONF_DIR, filmstrip_config
from plls_bench.rundirs.record_layout import record_path
from plls_bench.rundirs.run_dir import STATUS_DONE, Run, config_hash, variant_overrides


def filmed_presets() -> set[str]:
    """Presets one of whose trials is filmed (Figs 11, 19, 22): those a filmstrip config
    (``conf/filmstrip/<env>.yaml``) lists, for runners whose spec has a policy to film."""
    return set(_filmstrip_presets())


def _filmstrip_presets() -> dict[str, FilmstripConfig]:
    """Each filmed preset's filmstrip config, from ``conf/filmstrip/<env>.yaml``'s ``presets``."""
    strips = {env: filmstrip_config(env) for env in ENV_NAMES if (CONF_DIR / "filmstrip" / f"{env}.yaml").exists()}
    return {preset: strip for strip in strips.values() for preset in strip.presets}


def film_policies(plans: list[PresetPlan]) -> list[str]:
    """Film the first done trial that holds a policy (:func:`_film_target`) of each filmed preset
    (``budget.eval_max_steps`` caps the episode, as for its test episodes); a filmstrip already made of the same
    run with the same settings (its done marker, :class:`plls_bench.rundirs.run_dir.RunOutput`) is not redone.
    Returns the presets whose filmstrip failed."""
    failed, filmed = [], _filmstrip_presets()
    for plan in plans:
        strip = filmed.get(plan.experiment)
        # a variant (a sweep value) is not filmed
        if strip is None or not plan.trials or variant_overrides(plan.overrides):
            continue
        if not runner_spec(plan.runner).films:  # a filmstrip config that lists a preset with no policy
            print(f"[reproduce] {plan.experiment}: listed in conf/filmstrip/{plan.env}.yaml, but runner "
                  f"{plan.runner} has no policy to film", flush=True)
            failed.append(f"{plan.experiment} (filmstrip)")
            continue
        target = _film_target(plan)
        if target is None:
            print(f"[reproduce] {plan.experiment}: no filmstrip, no done trial holds a policy "
                  f"(seed={plan.trials[0].seed} first)", flush=True)
            continue
        trial, run = target
        # the strip names the hash its run dir stored (filmstrip.py), which predates a hashing rule
        # for runs made before it; _film_target has checked that run is this config's
        run_hash, cap = (run.read_status() or {}).get("config_hash"), trial.cfg.budget.eval_max_steps
        if run.output("filmstrip").is_made(strip.output_hash(run_hash, STATUS_DONE, cap), legacy=_legacy_hash):
            print(f"[reproduce] {plan.experiment}: filmstrip already made", flush=True)
            continue
        command = [sys.executable, "-m", "plls_bench.film", str(run.path),
                   *(["--max-steps", str(cap)] if cap else [])]
        if subprocess.run(command).returncode != 0:
            failed.append(f"{plan.experiment} (filmstrip)")
    return failed


def _film_target(plan: PresetPlan) -> tuple[Trial, Run] | None:
    """The lowest-seed trial that is done, in its run dir or else in its committed record (the strip
    then joins the record), and holds a policy: a record of a run exported before records carried
    checkpoints has none, so the next seed's is filmed."""
    policy_files = runner_spec(plan.runner).load_policy_files
    for trial in plan.trials:
        run_hash = config_hash(trial.cfg)
        for run in (Run(trial.run_dir), *([Run(record_path(trial.run_dir))] if trial.recorded else [])):
            if run.is_done(run_hash) and (policy_files is None or policy_files()(run.path)):
                return trial, run
    return None


def _legacy_hash(path: Path) -> str | None:
    """A strip from before done markers: its identity from the filmstrip.json it ends with."""
    meta = read_json(path / "filmstrip.json")
    return filmstrip_hash(meta) if isinstance(meta, dict) else None
