"""The run-directory contract: paths, status, provenance and metrics streams (atomic files:
:mod:`plls_bench.core.atomic_files`).

A run lives at ``<runs_dir>/<experiment>/<variant>/seed=<k>/`` and holds::

    .hydra/               Hydra's own record of the composed config and overrides
    config.json           the typed, resolved config and its hash (what the collector reads)
    provenance.json       git sha + dirty flag, package versions, command, host, device used, starts
    metrics/<stream>.jsonl one JSON record per line (train, eval, repr_train, ...)
    metrics/*.json        summaries, e.g. :data:`PARAMS_FILE` and :data:`ARCHITECTURE_FILE`
    checkpoints/          whatever the runner needs to resume
    status.json           written last and atomically: running -> done | stopped (time limit, SIGTERM)
                          | failed (with the error)
    filmstrip/            a sub-output made after the run (:data:`RUN_OUTPUTS`, :class:`RunOutput`):
                          its files, then done.json with its own config hash

Nothing outside this module writes into a run directory except through :class:`Run`.
"""
from __future__ import annotations

import copy
import re
import shutil
import time
from collections.abc import Callable, Iterable
from dataclasses import asdict, is_dataclass
from pathlib import Path
from typing import Any

from plls_bench.core.atomic_files import (
    append_jsonl,
    atomic_write_bytes,
    atomic_write_json,
    jsonl_line,
    read_json,
    read_jsonl,
)
from plls_bench.core.hashing import stable_hash

STATUS_RUNNING, STATUS_DONE, STATUS_FAILED = "running", "done", "failed"
STATUS_STOPPED = "stopped"  # ended early (time_limit_min, at a checkpoint; or SIGTERM); the next launch resumes it
SUPERSEDED_DIR = ".superseded"  # under runs_dir: runs whose config changed, moved aside, never deleted
# Config keys that do not change what a run computes: left out of the config hash.
HASH_EXCLUDED_KEYS = ("runs_dir", "progress", "torch_threads", "variant", "time_limit_min", "retain_freed_memory")
# Keys added after runs were recorded: at these values (which compute what the runs before the key
# computed) they are left out of the hash, so those runs and their committed records keep their
# identity. A key set to anything else is hashed like every other.
HASH_NEUTRAL_DEFAULTS: dict[str, Any] = {
    "algo.ppo.use_sde": False, "algo.ppo.sde_sample_freq": 0,
    "algo.ppo.normalize_obs": False, "algo.ppo.normalize_reward": False,
    "env.backend": "gymnasium", "precision": "fp32", "algo.dbc.encoder": "bisim", "env.visuals": "stock",
}
# Nested keys that change speed, never results (envpool steps each env on its own random stream,
# whichever thread runs it): always left out of the hash, as torch_threads is.
HASH_EXCLUDED_NESTED = ("env.backend_threads",)
# Nested keys of the plan, not of a run: how many seeds a preset launches. Seed k computes the same
# whatever the count, so adding trials to an arm leaves its finished trials done (issue: trial counts
# raised to the verdict protocol's). Run dirs and records stored before this rule are identified by
# recomputing their stored config's hash (:func:`stored_identity`), never by the hash they wrote.
HASH_PLAN_KEYS = ("budget.trials",)
# Config keys hashed at a fixed value, whatever the config says. ``device`` changes where a run
# computes, not what it computes statistically (CPU and GPU kernels differ in rounding only), so it
# must not tell runs apart. It was hashed as "cpu" before ``auto`` became the default; hashing that
# value instead of dropping the key keeps the hashes of existing runs, which stay done/resumable.
HASH_PINNED_KEYS = {"device": "cpu"}
# Overrides left out of the run dir's variant name although they change a result, or are no config
# key: already in the path (experiment, seed), the profile (one run dir serves every profile; the
# config hash tells them apart and supersedes) and Hydra's launcher. conf/config.yaml's
# hydra.job.config.override_dirname.exclude_keys is these plus :func:`unhashed_keys`: Hydra reads
# that list from yaml, so tests/test_run_dir.py checks the two agree.
VARIANT_EXCLUDED_KEYS = ("experiment", "seed", "budget", "hydra/launcher")
# What a method's modules are (Table 3, Figs. 12 and 17), written by each runner that builds a
# model and read by the collector: parameter counts, and the layers of each module.
PARAMS_FILE = "metrics/params.json"
ARCHITECTURE_FILE = "metrics/architecture.json"
# Sub-outputs made from a finished run by a later command, each in ``<run dir>/<name>/``.
RUN_OUTPUTS = ("filmstrip",)


# --------------------------------------------------------------------------- config identity
def config_dict(cfg: Any) -> dict[str, Any]:
    """A plain dict of a (dataclass) config."""
    return asdict(cfg) if is_dataclass(cfg) else dict(cfg)


def hashed_config(config: dict[str, Any], excluded: tuple[str, ...] = HASH_EXCLUDED_KEYS) -> dict[str, Any]:
    """What identifies a config: less the ``excluded`` top-level keys and
    :data:`HASH_EXCLUDED_NESTED`, :data:`HASH_PINNED_KEYS` at their pinned values and the keys of
    :data:`HASH_NEUTRAL_DEFAULTS` at their neutral values left out."""
    data = copy.deepcopy({k: HASH_PINNED_KEYS.get(k, v) for k, v in config.items() if k not in excluded})
    for dotted in (*HASH_NEUTRAL_DEFAULTS, *HASH_EXCLUDED_NESTED, *HASH_PLAN_KEYS):
        *parents, leaf = dotted.split(".")
        node: Any = data
        for part in parents:
            node = node.get(part) if isinstance(node, dict) else None
        if isinstance(node, dict) and leaf in node and (
                dotted not in HASH_NEUTRAL_DEFAULTS or node[leaf] == HASH_NEUTRAL_DEFAULTS[dotted]):
            del node[leaf]
    return data


def unhashed_keys() -> tuple[str, ...]:
    """Every key that changes no result, dotted: excluded, nested-excluded and pinned alike."""
    return (*HASH_EXCLUDED_KEYS, *HASH_EXCLUDED_NESTED, *HASH_PLAN_KEYS, *HASH_PINNED_KEYS)


def config_hash(cfg: Any) -> str:
    """Identity of what a run computes: :func:`hashed_config` of its config."""
    return stable_hash(hashed_config(config_dict(cfg)))


def stored_identity(run_dir: str | Path, fallback: str | None = None) -> str | None:
    """The config hash, under today's rules, of the config a run dir (or a record of one) stored
    in ``config.json``; ``fallback`` when it stores none. Recomputed rather than read, so a rule that
    drops a key from the hash (:data:`HASH_PLAN_KEYS`) keeps every earlier run identified."""
    stored = read_json(Path(run_dir) / "config.json")
    config = stored.get("config") if isinstance(stored, dict) else None
    return config_hash(config) if isinstance(config, dict) else fallback


# --------------------------------------------------------------------------- paths
_SAFE = re.compile(r"[^A-Za-z0-9_.,=+-]")


def backend_tag(backend: str) -> str:
    """How a non-default env backend names itself in run-dir variants and rate keys (empty for
    gymnasium, the engine runs had before the key existed)."""
    return "" if backend == "gymnasium" else f"env.backend={backend}"


def variant_name(variant: str, override_dirname: str = "", backend: str = "gymnasium") -> str:
    """The run dir's variant part: an explicit ``variant``, else the overrides, else ``default``.

    A non-default ``env.backend`` always shows in the name, also when a profile (not the command
    line) chose it: runs of two simulators must never share a run dir."""
    if variant and variant != "auto":
        return variant
    name = _SAFE.sub("_", override_dirname.replace("/", "."))
    tag = backend_tag(backend)
    if tag and tag not in name.split(","):
        name = f"{name},{tag}" if name else tag
    return name[:120] or "default"


def variant_overrides(overrides: Iterable[str]) -> list[str]:
    """The ``key=value`` overrides that name a run dir's variant, as Hydra's ``override_dirname``
    keeps them: all but :data:`VARIANT_EXCLUDED_KEYS` and :func:`unhashed_keys`, sorted."""
    left_out = {*VARIANT_EXCLUDED_KEYS, *unhashed_keys()}
    return sorted(o for o in overrides if o.split("=", 1)[0].lstrip("+~") not in left_out)


def run_dir_path(runs_dir: str | Path, experiment: str, variant: str, seed: int) -> Path:
    return Path(runs_dir) / experiment / variant / f"seed={seed}"


# --------------------------------------------------------------------------- the run
class Run:
    """Owns one run directory; every write into it goes through here."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.metrics_dir = self.path / "metrics"
        self.checkpoints_dir = self.path / "checkpoints"

    # status ---------------------------------------------------------------
    @property
    def status_path(self) -> Path:
        return self.path / "status.json"

    def read_status(self) -> dict[str, Any] | None:
        return read_json(self.status_path)

    def write_status(self, state: str, **fields: Any) -> None:
        atomic_write_json(self.status_path, {"state": state, "updated": _now(), **fields})

    def is_done(self, cfg_hash: str) -> bool:
        """Finished, with the config whose hash (today's rules) is ``cfg_hash``."""
        status = self.read_status() or {}
        return status.get("state") == STATUS_DONE and self.identity() == cfg_hash

    def identity(self) -> str | None:
        """Today's hash of the config this run dir stored (:func:`stored_identity`); without a
        config.json, the hash its status names."""
        return stored_identity(self.path, (self.read_status() or {}).get("config_hash"))

    # config and provenance -----------------------------------------------
    def prepare(self, cfg: Any, cfg_hash: str) -> None:
        """Create the layout, write config.json and add this start to provenance.json."""
        self.metrics_dir.mkdir(parents=True, exist_ok=True)
        self.checkpoints_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_json(self.path / "config.json", {"config_hash": cfg_hash, "config": config_dict(cfg)})
        from plls_bench.rundirs.provenance import collect_provenance  # lazy: imports torch & friends

        previous = read_json(self.path / "provenance.json") or {}
        starts = list(previous.get("starts", [])) + [collect_provenance(getattr(cfg, "device", "auto"),
                                                                     getattr(cfg, "precision", "fp32"))]
        atomic_write_json(self.path / "provenance.json", {**starts[0], "starts": starts})

    def read_config(self) -> dict[str, Any] | None:
        return read_json(self.path / "config.json")

    def supersede(self, runs_dir: str | Path) -> Path:
        """Move this run dir (whose config changed) aside under ``runs_dir/.superseded``."""
        old_hash = (self.read_config() or {}).get("config_hash", "unknown")
        rel = self.path.resolve().relative_to(Path(runs_dir).resolve())
        target = Path(runs_dir) / SUPERSEDED_DIR / rel.parent / f"{rel.name}.{old_hash}.{int(time.time())}"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(self.path), str(target))
        return target

    # metrics ----------------------------------------------------------------
    def metrics_path(self, stream: str) -> Path:
        return self.metrics_dir / f"{stream}.jsonl"

    def log(self, stream: str, record: dict[str, Any]) -> None:
        """Append ``record`` to ``metrics/<stream>.jsonl``."""
        append_jsonl(self.metrics_path(stream), record)

    def write_metrics(self, stream: str, records: Iterable[dict[str, Any]]) -> None:
        """Atomically replace ``metrics/<stream>.jsonl`` with ``records`` (a stream copied whole,
        which a rerun must replace, not append to)."""
        atomic_write_bytes(self.metrics_path(stream), "".join(map(jsonl_line, records)).encode())

    def read_metrics(self, stream: str) -> list[dict[str, Any]]:
        return read_jsonl(self.metrics_path(stream))

    def truncate_metrics(self, stream: str, keep: Callable[[dict[str, Any]], bool]) -> int:
        """Atomically rewrite a stream keeping only records where ``keep`` holds (used on resume,
        so rows logged after the checkpoint being resumed are not duplicated). Returns rows dropped."""
        path = self.metrics_path(stream)
        if not path.exists():
            return 0
        records = read_jsonl(path)
        kept = [r for r in records if keep(r)]
        self.write_metrics(stream, kept)
        return len(records) - len(kept)

    def write_json(self, relpath: str, obj: Any) -> Path:
        """Atomically write a JSON file at ``relpath`` inside the run dir."""
        path = self.path / relpath
        atomic_write_json(path, obj)
        return path

    def write_bytes(self, relpath: str, data: bytes) -> Path:
        path = self.path / relpath
        atomic_write_bytes(path, data)
        return path

    def output(self, name: str) -> RunOutput:
        """The declared sub-output ``name`` (:data:`RUN_OUTPUTS`) of this run."""
        if name not in RUN_OUTPUTS:
            raise KeyError(f"{name!r} is not a declared run output; declared: {', '.join(RUN_OUTPUTS)}")
        return RunOutput(self.path / name)


class RunOutput:
    """A sub-output directory: every file written atomically, then ``done.json`` with the hash of
    the config that made it, so an output cut off half-way is never taken for made."""

    MARKER = "done.json"

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def is_made(self, cfg_hash: str, legacy: Callable[[Path], str | None] | None = None) -> bool:
        """Made with ``cfg_hash``. Outputs written before they had a marker: ``legacy(path)``
        reads their hash from their own files (None: not made)."""
        marker = read_json(self.path / self.MARKER)
        if marker is None:
            return legacy is not None and legacy(self.path) == cfg_hash
        return marker.get("state") == STATUS_DONE and marker.get("config_hash") == cfg_hash

    def write(self, cfg_hash: str, files: dict[str, Any]) -> None:
        """Write ``files`` in order (bytes as they are, anything else as JSON), then the marker."""
        (self.path / self.MARKER).unlink(missing_ok=True)  # stale from here until every file is new
        for relpath, content in files.items():
            if isinstance(content, bytes):
                atomic_write_bytes(self.path / relpath, content)
            else:
                atomic_write_json(self.path / relpath, content)
        atomic_write_json(self.path / self.MARKER, {"state": STATUS_DONE, "config_hash": cfg_hash, "updated": _now()})


def iter_run_dirs(runs_dir: str | Path) -> Iterable[Path]:
    """Every ``<experiment>/<variant>/seed=<k>`` dir under ``runs_dir`` (artifacts and superseded
    runs excluded), sorted."""
    root = Path(runs_dir)
    for path in sorted(root.glob("*/*/seed=*")):
        if path.is_dir() and path.parts[-3] not in ("artifacts", SUPERSEDED_DIR):
            yield path


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")
