"""A result's verdict for a person: pass, warn or fail, each check with its figure, the
threshold it was held to and, when not a pass, what to do. It travels in the reply
(`"verdict"`), so every door shows the same one: the CLI and `omnisort ctl` print it as a few
lines, `--json` keeps it inside the whole reply.

The thresholds are the product's own figures, each named where it is used (docs/verdicts.md
gives them with their reasons), never fitted to one data set.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from omnisort_hw.pipeline.replies import CheckReply, Level, VerdictReply

_RANK: dict[str, int] = {"pass": 0, "warn": 1, "fail": 2}


@dataclass(frozen=True)
class Check:
    """One criterion: its name, its level, the figure measured, the threshold, the advice."""

    name: str
    level: Level
    figure: str
    threshold: str
    advice: str = ""

    def to_dict(self) -> CheckReply:
        out: CheckReply = {
            "name": self.name,
            "level": self.level,
            "figure": self.figure,
            "threshold": self.threshold,
        }
        if self.advice:
            out["advice"] = self.advice
        return out


def graded(
    name: str,
    value: float,
    unit: str,
    warn_above: float,
    fail_above: float | None = None,
    advice: str = "",
    digits: int = 3,
) -> Check:
    """A figure that is better small: pass up to `warn_above`, warn up to `fail_above` (when
    given), fail beyond; a figure that is not a number never passes."""
    figure = f"{value:.{digits}g} {unit}".strip()
    if value <= warn_above:
        level: Level = "pass"
    elif fail_above is None or value <= fail_above:
        level = "warn"
    else:
        level = "fail"
    limits = f"pass <= {warn_above:.{digits}g} {unit}".strip()
    if fail_above is not None:
        limits += f", fail > {fail_above:.{digits}g} {unit}".rstrip()
    return Check(name, level, figure, limits, advice if level != "pass" else "")


def none_of(name: str, count: int, level: Level, advice: str = "") -> Check:
    """A count of things that went wrong: `level` (with `advice`) unless it is 0."""
    return Check(name, level if count else "pass", str(count), "0", advice if count else "")


def at_least(name: str, count: int, minimum: int, level: Level, advice: str) -> Check:
    """A count that must reach `minimum`; `level` when it does not."""
    ok = count >= minimum
    return Check(name, "pass" if ok else level, str(count), f">= {minimum}", "" if ok else advice)


@dataclass(frozen=True)
class Verdict:
    """The checks of one result; its level is the worst of theirs."""

    what: str
    checks: tuple[Check, ...]

    @property
    def level(self) -> Level:
        return worst([c.level for c in self.checks])

    def to_dict(self) -> VerdictReply:
        return {
            "level": self.level,
            "what": self.what,
            "checks": [c.to_dict() for c in self.checks],
        }


def verdict_lines(verdict: Mapping[str, Any]) -> list[str]:
    """A reply's `verdict` as lines for a terminal: the level first, then each check."""
    lines = [f"{str(verdict['level']).upper()}: {verdict['what']}"]
    for check in verdict.get("checks", ()):
        line = f"  {check['level']:<4}  {check['name']}: {check['figure']} ({check['threshold']})"
        if check.get("advice"):
            line += f"; {check['advice']}"
        lines.append(line)
    return lines


def worst(levels: Sequence[Level]) -> Level:
    """The worst of some levels (pass when none)."""
    rank = max((_RANK[lv] for lv in levels), default=0)
    levels_by_rank: tuple[Level, ...] = ("pass", "warn", "fail")
    return levels_by_rank[rank]
