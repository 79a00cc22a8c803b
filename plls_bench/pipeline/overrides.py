"""Ablation overrides of ``reproduce --override KEY=VALUE``: any config key changed for every preset
a launch runs, each change in a run-dir variant of its own beside the preset's default runs.

An override is a Hydra command-line override, as ``python -m plls_bench`` takes it; the overrides
given together make one variant, and ``KEY=V1,V2`` (Hydra's sweep syntax) makes one variant per
value. Keys with an option of their own (the profile, the seeds, the runs dir, the precision, Hydra's
settings) and keys that change no result (so would name no variant) are refused here, before anything
is planned; a key the config does not have is refused when the plan composes it (``plan_profile``).
An override of a key the preset never reads (a representation's key while that representation is off)
still plans and runs its trials; the dry run says so (:func:`inert_overrides`).
"""
from __future__ import annotations

from plls_bench.config import Config, ConfigError
from plls_bench.rundirs.composition import expand_sweeps
from plls_bench.rundirs.run_dir import unhashed_keys

# Keys reproduce sets itself, each with the option that sets it.
OWN_OPTIONS = {"budget": "--profile", "seed": "the profile's budget.trials", "runs_dir": "--runs",
               "precision": "--precision", "experiment": "--only", "hydra": "--hydra",
               "hydra/launcher": "--launcher"}

# Representation groups whose keys build nothing while the group is off (``kind: none``,
# conf/repr/action/none.yaml and conf/repr/state/none.yaml): the module each names.
SWITCHED_GROUPS = {"action": "V_a", "state": "V_s"}


def override_key(override: str) -> str:
    """The dotted key of ``key=value`` (a leading ``+``, ``++`` or ``~`` left off)."""
    return override.split("=", 1)[0].lstrip("+~")


def check_override(override: str) -> None:
    """ConfigError naming ``override`` when it is no ``KEY=VALUE``, or sets a key reproduce sets
    through an option of its own, or a key that changes no result."""
    key = override_key(override)
    if "=" not in override or not key:
        raise ConfigError(f"--override takes KEY=VALUE, got {override!r}")
    root = key.split(".", 1)[0]
    if key in OWN_OPTIONS or root in OWN_OPTIONS:
        option = OWN_OPTIONS.get(key) or OWN_OPTIONS[root]
        raise ConfigError(f"--override {override}: {key} is set by {option}, not by an override")
    if key in unhashed_keys():
        raise ConfigError(f"--override {override}: {key} changes no result (it is left out of the config "
                          "hash), so it would name no variant")


def override_variants(overrides: list[str]) -> list[tuple[str, ...]]:
    """The variants ``overrides`` make, each a tuple of ``key=value`` settings (none without
    overrides): one per combination of the values of ``KEY=V1,V2`` sweeps. ConfigError names a bad one."""
    if not overrides:
        return []
    for override in overrides:
        check_override(override)
    try:
        jobs = expand_sweeps(list(overrides))
    except Exception as err:  # Hydra's override grammar: an unbalanced bracket, a stray quote
        raise ConfigError(f"--override {' '.join(overrides)}: not a Hydra override ({err})") from err
    return list(dict.fromkeys(tuple(job) for job in jobs))


def inert_overrides(cfg: Config, overrides: tuple[str, ...]) -> list[str]:
    """``key (V_x off)`` for each of ``overrides`` that sets a key of a representation that is off
    in the composed ``cfg``: nothing reads it, so the variant's trials compute what the preset's do."""
    inert = []
    for override in overrides:
        parts = override_key(override).split(".")
        if len(parts) > 2 and parts[0] == "repr" and parts[1] in SWITCHED_GROUPS \
                and getattr(cfg.repr, parts[1]).kind == "none":
            inert.append(f"{'.'.join(parts)} ({SWITCHED_GROUPS[parts[1]]} off)")
    return inert
