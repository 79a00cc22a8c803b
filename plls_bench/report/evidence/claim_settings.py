"""The claims' decision settings, ``results/paper/claims.yaml``: the protocol's alpha, power, least
trials and "final" tail; per comparison its equivalence margin, planned trials and Holm family;
per task its solve criterion; the published anchors' dispersion; the random-policy gates; and the
claims the paper leaves open to several readings. Read once per report, checked against the rows
of ``claims.csv`` so that a typo fails naming the key."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from plls_bench.report.evidence.looks import least_rejecting_n

SETTINGS_FILE = "claims.yaml"
PROTOCOL_KEYS = ("alpha", "power", "min_n", "final_tail", "threshold_min_n", "median_coverage")
COMPARISON_KEYS = ("margin", "planned_n", "primary", "paper_n")
DISPERSIONS = ("seeds", "episodes")
COMPARISON_KINDS = ("p_improvement", "std_gap", "ahead_from", "sweep_best")  # rows the Welch protocol decides


@dataclass(frozen=True)
class ComparisonSettings:
    margin: float | None
    planned_n: int
    primary: bool
    paper_n: int | None


@dataclass(frozen=True)
class ClaimSettings:
    alpha: float
    power: float
    min_n: int
    final_tail: int
    threshold_min_n: int
    median_coverage: float
    solved_at: dict[str, float | None]
    comparisons: dict[str, ComparisonSettings]
    anchors: dict[str, tuple[str, int | None]]          # claim -> (dispersion, published n)
    random_gates: dict[str, tuple[str, str]]             # claim -> (file, dotted key)
    readings: list[tuple[str, tuple[str, ...]]] = field(default_factory=list)  # (reading, rows of one claim)

    @property
    def family_size(self) -> int:
        """The primary comparison rows Holm corrects together (all that are declared, tested or not)."""
        return sum(c.primary for c in self.comparisons.values())

    def planned(self, claim: str) -> int | None:
        """The trials per arm a comparison row is judged at, once; None for a row without a plan."""
        return self.comparisons[claim].planned_n if claim in self.comparisons else None


def _fail(path: Path, where: str, problem: str) -> ValueError:
    return ValueError(f"{path}: {where}: {problem}")


def _mapping(node: Any, path: Path, where: str) -> dict[str, Any]:
    if not isinstance(node, dict):
        raise _fail(path, where, "expected a mapping")
    return node


def _known(rows: set[str] | None, names: list[str], path: Path, where: str) -> None:
    unknown = [] if rows is None else [n for n in names if n not in rows]
    if unknown:
        raise _fail(path, where, f"not a claim of claims.csv: {unknown[0]!r}")


def _comparison(node: Any, path: Path, where: str) -> ComparisonSettings:
    node = _mapping(node, path, where)
    extra = sorted(set(node) ^ set(COMPARISON_KEYS))
    if extra:
        raise _fail(path, where, f"keys must be {', '.join(COMPARISON_KEYS)} (wrong or missing: {', '.join(extra)})")
    margin, planned, paper = node["margin"], node["planned_n"], node["paper_n"]
    if margin is not None and not (isinstance(margin, (int, float)) and margin > 0):
        raise _fail(path, f"{where}.margin", f"a positive number or null, got {margin!r}")
    if not isinstance(planned, int) or planned < 2 or not isinstance(node["primary"], bool):
        raise _fail(path, where, f"planned_n must be an integer >= 2 and primary true/false, got {planned!r}, "
                                 f"{node['primary']!r}")
    return ComparisonSettings(None if margin is None else float(margin), planned, node["primary"],
                              None if paper is None else int(paper))


def _protocol(node: Any, path: Path) -> dict[str, Any]:
    node = _mapping(node, path, "protocol")
    extra = sorted(set(node) ^ set(PROTOCOL_KEYS))
    if extra:
        raise _fail(path, "protocol", f"keys must be {', '.join(PROTOCOL_KEYS)} (wrong or missing: {', '.join(extra)})")
    if not (0 < node["alpha"] < 0.5 and 0 < node["power"] < 1 and 0 < node["median_coverage"] < 1):
        raise _fail(path, "protocol", "alpha in (0, 0.5), power and median_coverage in (0, 1)")
    if min(node["min_n"], node["final_tail"], node["threshold_min_n"]) < 1:
        raise _fail(path, "protocol", "min_n, final_tail and threshold_min_n must be at least 1")
    return node


def load_settings(paper_dir: Path, claim_names: list[str] | None) -> ClaimSettings:
    """``paper_dir/claims.yaml``, checked against ``claim_names`` (the rows of claims.csv); ``None``
    checks no names (a view that reads only the protocol; the claims table checks them)."""
    path = paper_dir / SETTINGS_FILE
    try:
        raw = _mapping(yaml.safe_load(path.read_text()), path, "top level")
    except OSError as err:
        raise ValueError(f"{path}: cannot read the claims' decision settings ({err})") from None
    rows = None if claim_names is None else set(claim_names)
    protocol = _protocol(raw.get("protocol"), path)
    comparisons = _mapping(raw.get("comparisons", {}), path, "comparisons")
    anchors = _mapping(raw.get("anchors", {}), path, "anchors")
    gates = _mapping(raw.get("random_gates", {}), path, "random_gates")
    for where, names in (("comparisons", comparisons), ("anchors", anchors), ("random_gates", gates)):
        _known(rows, list(names), path, where)
    for name, node in anchors.items():
        if _mapping(node, path, f"anchors.{name}").get("dispersion") not in DISPERSIONS:
            raise _fail(path, f"anchors.{name}.dispersion", f"one of {', '.join(DISPERSIONS)}")
    readings = []
    for i, node in enumerate(raw.get("readings", [])):
        node = _mapping(node, path, f"readings[{i}]")
        _known(rows, list(node.get("rows", [])), path, f"readings[{i}].rows")
        readings.append((str(node["reading"]), tuple(node["rows"])))
    solved = {str(k): (None if v is None else float(v))
              for k, v in _mapping(raw.get("solved_at", {}), path, "solved_at").items()}
    settings = ClaimSettings(
        float(protocol["alpha"]), float(protocol["power"]), int(protocol["min_n"]), int(protocol["final_tail"]),
        int(protocol["threshold_min_n"]), float(protocol["median_coverage"]), solved,
        {k: _comparison(v, path, f"comparisons.{k}") for k, v in comparisons.items()},
        {k: (v["dispersion"], v.get("n")) for k, v in anchors.items()},
        {k: (str(v["file"]), str(v["key"])) for k, v in gates.items()}, readings)
    _check_plans(settings, path)
    return settings


def _check_plans(settings: ClaimSettings, path: Path) -> None:
    """Every planned n is at least the protocol's minimum and an n at which the row's test can reject
    at all: alpha / (primary rows) at Holm's first step, alpha for a sensitivity reading."""
    for name, plan in settings.comparisons.items():
        level = settings.alpha / settings.family_size if plan.primary else settings.alpha
        need = max(settings.min_n, least_rejecting_n(level))
        if plan.planned_n < need:
            raise _fail(path, f"comparisons.{name}.planned_n",
                        f"{plan.planned_n} trials per arm cannot decide this row: it needs at least {need} (the "
                        f"protocol's min_n {settings.min_n}; a p of {level:.3g} needs 2 / C(2n, n) <= {level:.3g})")


def check_rows(settings: ClaimSettings, rows: list[dict[str, str]], paper_dir: Path) -> None:
    """Every comparison row of claims.csv has its claims.yaml entry (without one it would be decided
    outside the Holm family, with no margin or planned n), and every published final return with a
    ± has its dispersion declared (or is a random-policy gate), with the threshold that implies."""
    path = paper_dir / SETTINGS_FILE
    for row in rows:
        name = row["claim"]
        if row["kind"] in COMPARISON_KINDS and name not in settings.comparisons:
            raise _fail(path, "comparisons", f"no entry for the {row['kind']} row {name!r} (every comparison row "
                                             f"declares {', '.join(COMPARISON_KEYS)})")
        if row["kind"] != "final_return" or not row["paper_pm"] or name in settings.random_gates:
            continue
        if name not in settings.anchors:
            raise _fail(path, "anchors", f"no entry for {name!r}: its published ± needs its dispersion declared")
        dispersion, _ = settings.anchors[name]
        value, spread = float(row["paper_value"]), float(row["paper_pm"])
        below = row["rule"] in ("at_least", "greater_than")  # the suite must clear the anchor from below
        implied = value - (spread if below else -spread) if dispersion == "seeds" else value
        if not math.isclose(float(row["threshold"]), implied, rel_tol=1e-9):
            raise ValueError(f"{paper_dir / 'claims.csv'}: {name!r}: threshold {row['threshold']}, but "
                             f"{value:g} ± {spread:g} over {dispersion} implies {implied:g}")


def dispersion_text(dispersion: str, n: int | None) -> str:
    """How a published ± is read, as the row states it."""
    if dispersion == "seeds":
        return f"published ± is an SD over {n if n else 'its'} seeds: threshold mean - 1 SD"
    return "published ± is over one agent's evaluation episodes, not seeds: threshold the published mean"

