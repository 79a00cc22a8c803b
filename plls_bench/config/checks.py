"""Validation helpers shared by the config schemas: one :class:`ConfigError` naming the key."""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import fields
from pathlib import Path

from omegaconf import MISSING


class ConfigError(ValueError):
    """A config value is invalid; the message names the key."""


def check(ok: bool, key: str, message: str) -> None:
    """Raise :class:`ConfigError` naming ``key`` unless ``ok``."""
    if not ok:
        raise ConfigError(f"{key}: {message}")


def check_positive(value: float, key: str) -> None:
    check(isinstance(value, (int, float)) and math.isfinite(value) and value > 0, key,
          f"must be > 0, got {value!r}")


def check_nonnegative(value: float, key: str) -> None:
    check(isinstance(value, (int, float)) and math.isfinite(value) and value >= 0, key,
          f"must be >= 0, got {value!r}")


def check_choice(value: str, choices: tuple[str, ...], key: str) -> None:
    check(value in choices, key, f"unknown value {value!r}; choose one of {', '.join(choices)}")


def check_fraction(value: float, key: str, *, open_right: bool = True) -> None:
    upper_ok = value < 1 if open_right else value <= 1
    check(0 < value and upper_ok, key, f"must be in (0, 1{')' if open_right else ']'}, got {value!r}")


def check_writable_dir(path: str, key: str) -> None:
    """Raise :class:`ConfigError` naming ``key`` unless ``path`` is a directory this process can
    create or write into. Leaves nothing behind: the nearest existing ancestor must be a directory
    with write and search permission that accepts a new entry. A machine-side check for commands
    about to write (not part of :meth:`Validated.validate`: recorded configs name paths of other
    machines). As root, only a read-only mount fails ``os.access``; a mode-0555 directory still
    passes, as root may write there, and a folder that passes ``os.access`` but takes no new entry
    (``/proc``) fails the probe."""
    target = Path(os.path.abspath(path))
    existing = next(p for p in (target, *target.parents) if p.exists())  # "/" always exists
    check(existing.is_dir(), key, f"cannot create or write {path}: {existing} is not a directory")
    check(os.access(existing, os.W_OK | os.X_OK), key, f"cannot create or write {path}: {existing} is not writable")
    refused = _refuses_entries(existing)
    check(refused is None, key, f"cannot create or write {path}: {existing} takes no new entry ({refused})")


def _refuses_entries(folder: Path) -> str | None:
    """Why ``folder`` refuses a new entry although its mode allows one (a pseudo file system such as
    ``/proc``, a full disk), or None. Tried with a temporary folder, removed at once."""
    try:
        probe = tempfile.mkdtemp(prefix=".plls-write-check-", dir=folder)
    except OSError as err:
        return err.strerror or type(err).__name__
    os.rmdir(probe)
    return None


class Validated:
    """Runs :meth:`validate` after construction, once every field has a value.

    OmegaConf instantiates schemas with ``???`` placeholders when it registers them; those
    instances are templates, not configs, so they are not validated. A config converted with
    ``OmegaConf.to_object`` has no placeholders left (OmegaConf refuses missing values first).
    """

    def __post_init__(self) -> None:
        if not any(getattr(self, f.name) == MISSING for f in fields(self)):  # type: ignore[arg-type]
            self.validate()

    def validate(self) -> None:
        """Check value ranges and choices; raise :class:`ConfigError` naming the key."""
