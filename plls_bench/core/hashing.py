"""The one digest that identifies configs, artifacts and sub-outputs: the SHA-256 of canonical JSON.

It sits below the config layer (sub-output settings hash themselves with it) and below the run
directories (config hashes), so it imports nothing of the package.
"""
from __future__ import annotations

import hashlib
import json
from typing import Any


def stable_hash(obj: Any, length: int = 16) -> str:
    """Hex digest of the canonical JSON of ``obj`` (sorted keys)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:length]
