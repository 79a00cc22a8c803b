"""Which trials of one experiment the collector pools: two configs are one experiment when they
agree on every key but the seed and the keys that change no result (the device a seed ran on, say).
"""
from __future__ import annotations

from typing import Any

from plls_bench.core.hashing import stable_hash
from plls_bench.rundirs.run_dir import HASH_EXCLUDED_KEYS, HASH_NEUTRAL_DEFAULTS, HASH_PINNED_KEYS, hashed_config

# Trials of one experiment may differ in these and still be pooled: the device a seed ran on too.
NOT_IDENTITY = (*HASH_EXCLUDED_KEYS, *HASH_PINNED_KEYS, "seed")


def pooling_identity(config: dict[str, Any]) -> str:
    """A hash of ``config`` without the keys in :data:`NOT_IDENTITY`: equal for trials to pool."""
    return stable_hash(hashed_config(config, NOT_IDENTITY))


def config_diff(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """``"key: a vs b"`` for each dotted key whose value differs between two configs (a key one
    lacks counts as its neutral default), leaving out :data:`NOT_IDENTITY`; sorted by key."""
    fa, fb = _flatten(a), _flatten(b)
    keys = [k for k in sorted(set(fa) | set(fb))
            if fa.get(k, HASH_NEUTRAL_DEFAULTS.get(k)) != fb.get(k, HASH_NEUTRAL_DEFAULTS.get(k))
            and k.split(".")[0] not in NOT_IDENTITY]
    return [f"{k}: {fa.get(k)!r} vs {fb.get(k)!r}" for k in keys]


def _flatten(node: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(node, dict):
        return {prefix: node}
    out: dict[str, Any] = {}
    for key, value in node.items():
        out.update(_flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    return out
