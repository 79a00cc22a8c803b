"""Compose the shipped configs into a typed :class:`Config`, outside or before ``hydra.main``.

The entry point uses this to validate a command line before Hydra creates a run directory; tests
use it to build configs from the shipped yaml instead of by hand.
"""
from __future__ import annotations

import itertools
from dataclasses import replace
from pathlib import Path

from hydra import compose as hydra_compose
from hydra import initialize_config_dir
from omegaconf import OmegaConf

from plls_bench.config import Config, ConfigError, FilmstripConfig, register_configs, to_config
from plls_bench.config.runner_checks import runner_of
from plls_bench.core.atomic_files import read_json
from plls_bench.rundirs.record_layout import runs_dir_of
from plls_bench.rundirs.run_dir import variant_name

CONF_DIR = Path(__file__).resolve().parents[2] / "conf"
MAX_SWEEP_VALIDATION = 512  # a multirun larger than this is validated on its first jobs only


def register() -> None:
    """Register the schema and the resolvers of conf/config.yaml: the run-dir variant and the
    runner an algo implies (idempotent)."""
    register_configs()
    for name, resolver in (("plls_variant", variant_name), ("plls_runner", runner_of)):
        if not OmegaConf.has_resolver(name):
            OmegaConf.register_new_resolver(name, resolver)


def compose(overrides: list[str] | tuple[str, ...] = (), config_name: str = "config") -> Config:
    """The typed config for ``overrides`` (Hydra override syntax), validated."""
    register()
    try:
        with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3", job_name="run"):
            dcfg = hydra_compose(config_name=config_name, overrides=list(overrides))
    except ConfigError:
        raise
    except Exception as err:  # Hydra/OmegaConf composition errors: unknown group, typo, type
        raise ConfigError(describe_error(err)) from err
    return to_config(dcfg)


def filmstrip_config(env: str, overrides: list[str] | tuple[str, ...] = ()) -> FilmstripConfig:
    """``conf/filmstrip/<env>.yaml`` with ``overrides`` (``interval=8``), typed and validated."""
    strip = compose([f"env={env}", f"+filmstrip={env}", *(f"filmstrip.{o}" for o in overrides)]).filmstrip
    assert strip is not None
    return strip


def expand_sweeps(overrides: list[str]) -> list[list[str]]:
    """The override lists of each job of a multirun (sweeps like ``seed=0,1,2`` expanded)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    choices: list[list[str]] = []
    for override in OverridesParser.create().parse_overrides(overrides):
        if override.is_sweep_override():
            key = override.get_key_element()
            choices.append([f"{key}={value}" for value in override.sweep_string_iterator()])
        else:
            choices.append([override.input_line])
    return [list(job) for job in itertools.islice(itertools.product(*choices), MAX_SWEEP_VALIDATION)]


def describe_error(err: BaseException) -> str:
    """One line from a chain of Hydra/OmegaConf errors, keeping the parts that name the key."""
    parts: list[str] = []
    seen: BaseException | None = err
    while seen is not None:
        for line in str(seen).splitlines():
            line = line.strip()
            if line and not line.startswith(("object_type", "reference_type", "Set the environment",
                                              "Config search path", "provider=")) and line not in parts:
                parts.append(line)
        seen = seen.__cause__
    return " | ".join(parts) or type(err).__name__


def config_from_dict(data: dict) -> Config:
    """The typed config recorded in a run's ``config.json`` (validated again)."""
    register()
    return to_config(OmegaConf.merge(OmegaConf.structured(Config), data))


def recorded_config(run_dir: str | Path) -> Config:
    """The typed config of a run dir or record, its ``runs_dir`` moved to where the run lives now
    (:func:`~plls_bench.rundirs.record_layout.runs_dir_of`), so a record made elsewhere finds its V_s /
    V_a on any checkout. FileNotFoundError when there is no readable ``config.json``."""
    record = read_json(Path(run_dir) / "config.json")
    if record is None:
        raise FileNotFoundError(f"{run_dir}/config.json is missing: not a run directory")
    cfg = config_from_dict(record["config"])
    return replace(cfg, runs_dir=runs_dir_of(run_dir, cfg.runs_dir))
