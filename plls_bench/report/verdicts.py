"""A claim's verdict: the suite's interval read against the claim's rule and threshold (the rules
``results/paper/claims.csv`` may name)."""
from __future__ import annotations

import math
from dataclasses import dataclass

RULES = ("at_most", "at_least", "greater_than", "equal", "between")
REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE, NOT_RUN = ("reproduced", "not reproduced", "inconclusive",
                                                     "not run at this budget")
# A comparison whose baseline fails its own check (its ``requires`` row is not reproduced): a method
# beating, or losing to, a baseline that does not learn says nothing about the method.
NOT_MADE = "not made: baseline fails its check"
VERDICTS = (REPRODUCED, NOT_REPRODUCED, INCONCLUSIVE, NOT_RUN, NOT_MADE)


@dataclass(frozen=True)
class Estimate:
    """The suite's value for one claim and the 95% CI it is judged on."""

    value: float
    ci: tuple[float, float]
    text: str      # the suite's value as shown
    budget: str    # budgets and trial counts behind it
    reach: float = math.inf  # furthest x the runs reached on the claim's axis


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
