"""Declared ablation sweeps (``conf/sweep/<name>.yaml``): one preset, one config key, its values.

The one source of a sweep's definition: ``reproduce --sweep NAME`` plans and launches it, and the
results collector reads its arms. The arm of the preset's own value is the preset's own runs (no
override, variant ``default`` or the profile's backend tag); every other value is the command-line
override ``key=value``, so its runs land in the variant that override names (docs/configuration.md, "Ablations").
Nothing here imports torch or the simulators.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from plls_bench.config import ConfigError
from plls_bench.rundirs.composition import CONF_DIR, compose

SWEEP_DIR = CONF_DIR / "sweep"


@dataclass(frozen=True)
class Sweep:
    """``values`` of ``key`` on ``preset``; ``base`` is the preset's own value of ``key`` (as it
    composes), whose arm is the preset's own runs."""

    name: str
    preset: str
    key: str
    values: tuple[Any, ...]
    base: Any
    trials: int | None = None  # trials per value other than the preset's own; None: the preset's count

    @property
    def plan_overrides(self) -> tuple[str, ...]:
        """Settings of the plan, not of a run, for the values that run as overrides: their trial
        count (``budget.trials`` names no run-dir variant and is not hashed)."""
        return () if self.trials is None else (f"budget.trials={self.trials}",)

    def override(self, value: Any) -> str:
        """The command-line override of one value, as Hydra names the run-dir variant from it."""
        return f"{self.key}={value}"

    @property
    def others(self) -> tuple[Any, ...]:
        """The values that run as overrides (every value but the preset's own)."""
        return tuple(v for v in self.values if v != self.base)

    def arm_variant(self, value: Any) -> str | None:
        """The collector's variant for ``value``: None for the base runs, else the override."""
        return None if value == self.base else self.override(value)


def sweep_names() -> list[str]:
    return sorted(p.stem for p in SWEEP_DIR.glob("*.yaml"))


@cache
def load_sweep(name: str) -> Sweep:
    """``conf/sweep/<name>.yaml``, checked: the preset exists, the key is in its config, the values
    are distinct and include the preset's own value. Errors name the file and key."""
    if name not in sweep_names():
        raise ConfigError(f"--sweep: unknown sweep {name!r}; known: {', '.join(sweep_names()) or 'none'}")
    path = SWEEP_DIR / f"{name}.yaml"
    try:
        data = OmegaConf.to_container(OmegaConf.load(path))
    except (OSError, OmegaConfBaseException) as err:
        raise ConfigError(f"{path}: unreadable ({err})") from err
    keys = {"preset", "key", "values"}
    if not isinstance(data, dict) or not keys <= set(data) <= keys | {"trials"}:
        raise ConfigError(f"{path}: needs the keys preset, key, values (and optionally trials)")
    preset, key, values, trials = data["preset"], data["key"], data["values"], data.get("trials")
    if trials is not None and not (isinstance(trials, int) and not isinstance(trials, bool) and trials >= 1):
        raise ConfigError(f"{path}: trials: needs an int >= 1 (trials per value), got {trials!r}")
    if not (CONF_DIR / "experiment" / f"{preset}.yaml").is_file():
        raise ConfigError(f"{path}: preset: unknown experiment preset {preset!r}")
    if not isinstance(values, list) or len(values) < 2 or len(set(map(str, values))) != len(values):
        raise ConfigError(f"{path}: values: needs two or more distinct values, got {values!r}")
    base = _select(OmegaConf.structured(compose([f"+experiment={preset}"])), key, path)
    if base not in values:
        raise ConfigError(f"{path}: values: must include the preset's own {key}={base} (its runs are that arm)")
    for value in values:  # each override must compose: a bad value fails here, not in a launched job
        compose([f"+experiment={preset}", f"{key}={value}"])
    return Sweep(name, preset, key, tuple(values), base, trials)


def _select(cfg: Any, key: str, path: Any) -> Any:
    value = OmegaConf.select(cfg, key, default=_MISSING)
    if value is _MISSING or OmegaConf.is_config(value):
        raise ConfigError(f"{path}: key: {key!r} is not a value of the preset's config")
    return value


_MISSING = object()
