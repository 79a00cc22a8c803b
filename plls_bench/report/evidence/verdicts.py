"""A claim's verdict: the suite's interval read against the claim's rule and threshold (the rules
``results/paper/claims.csv`` may name), then against the verdict of the baseline check it requires."""
from __future__ import annotations

import math
from dataclasses import dataclass

from plls_bench.report.evidence.protocol import Comparison

RULES = ("at_most", "at_least", "greater_than", "equal", "between")
REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE, NOT_RUN = ("reproduced", "not reproduced", "inconclusive",
                                                     "not run at this budget")
# A comparison whose baseline fails its own check (its ``requires`` row is not reproduced, or not made): a method
# beating, or losing to, a baseline that does not learn says nothing about the method.
NOT_MADE = "not made: baseline fails its check"
# A comparison where neither arm solves the task (claims.yaml, solved_at) says nothing about either method.
NOT_SOLVED = "not made: neither arm solves the task"
# A comparison between the protocol's least trials and its planned n: its test is shown, but a verdict
# read at every count would be optional stopping (plls_bench.report.evidence.looks).
INTERIM = "interim (below the planned n)"
VERDICTS = (REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE, INTERIM, NOT_RUN, NOT_MADE, NOT_SOLVED)


@dataclass(frozen=True)
class Estimate:
    """The suite's value for one claim and the 95% interval it is judged on; a comparison row
    carries its :class:`Comparison` (judged on it, not on ``ci``), and ``unreadable`` says why
    a comparison cannot be read (neither arm solves the task)."""

    value: float
    ci: tuple[float, float]
    text: str      # the suite's value as shown
    budget: str    # budgets and trial counts behind it
    reach: float = math.inf  # furthest x the runs reached on the claim's axis
    comparison: Comparison | None = None
    unreadable: str | None = None


Judged = tuple[Estimate | None, str, str, str | None]  # a claim judged: (estimate, verdict, reason, budget text)


def verdict(rule: str, low: float, high: float, threshold: float, threshold_high: float = math.nan) -> str:
    """Judge the interval [low, high] (the CI, or the point twice) against the claim's rule."""
    if rule == "equal":
        return REPRODUCED if low == high == threshold else NOT_REPRODUCED
    on_side, off_side = {
        "at_most": (high <= threshold, low > threshold),
        "at_least": (low >= threshold, high < threshold),
        "greater_than": (low > threshold, high <= threshold),
        "between": (low >= threshold and high <= threshold_high, high < threshold or low > threshold_high),
    }[rule]
    return REPRODUCED if on_side else NOT_REPRODUCED if off_side else INCONCLUSIVE


def rule_text(claim: dict[str, str]) -> str:
    """The rule as the claims table shows it: "> 0.5", "in [900, 1500]"."""
    words = {"at_most": "≤", "at_least": "≥", "greater_than": ">", "equal": "=", "between": "in"}
    if claim["rule"] == "between":
        return f"in [{claim['threshold']}, {claim['threshold_high']}]"
    return f"{words[claim['rule']]} {claim['threshold']}"


def gated(outcome: str, reason: str, required: str, check_estimate: Estimate | None,
          check_outcome: str) -> tuple[str, str]:
    """A comparison's verdict and reason once its baseline check ``required`` is judged: not made if
    the check is not reproduced, or is itself not made (its own baseline fails); the comparison's own
    reading stays in the reason. Its own verdict otherwise, noting a check not (yet) reproduced."""
    value = f" ({check_estimate.text})" if check_estimate else ""
    if check_outcome in (NOT_REPRODUCED, NOT_MADE, NOT_SOLVED):
        state = {NOT_REPRODUCED: "not reproduced", NOT_MADE: "not made (its own baseline check fails)",
                 NOT_SOLVED: "not made (neither of its arms solves the task)"}[check_outcome]
        return NOT_MADE, f"its baseline check '{required}' is {state}{value}; its own reading: {outcome}, {reason}"
    if check_outcome == REPRODUCED or check_outcome == outcome == NOT_RUN:  # its reason names what is missing
        return outcome, reason
    return outcome, f"{reason}; its baseline check '{required}' is {check_outcome}"


def gate_all(claims: list[dict[str, str]], judged: dict[str, Judged]) -> dict[str, tuple[str, str]]:
    """Every claim's (verdict, reason) after its baseline checks: a row's ``requires`` may itself
    require another row, and a comparison reads its check's gated verdict, so a failure anywhere
    down the chain reaches it (``read_claims`` rejects a chain that leads back to its row)."""
    requires = {claim["claim"]: claim["requires"] for claim in claims}
    final: dict[str, tuple[str, str]] = {}

    def resolve(name: str) -> tuple[str, str]:
        if name not in final:
            _, outcome, reason, _ = judged[name]
            required = requires[name]
            if required:
                outcome, reason = gated(outcome, reason, required, judged[required][0], resolve(required)[0])
            final[name] = outcome, reason
        return final[name]

    for name in requires:
        resolve(name)
    return final
