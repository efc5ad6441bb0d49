"""A result's verdict for a person: pass, warn or fail, each check with its figure, the
threshold it was held to and, when not a pass, what to do. It travels in the reply
(`"verdict"`), so every door shows the same one: the CLI and `omnisort ctl` print it as a few
lines, `--json` keeps it inside the whole reply.

The thresholds are the product's own figures, each named where it is used (docs/verdicts.md
gives them with their reasons), never fitted to one data set.
"""

from __future__ import annotations

from collections.abc import Mapping

from omnisort_hw.pipeline.replies import CheckReply, Level, VerdictReply
from omnisort_hw.wire_records import from_wire

Check = CheckReply
"""One criterion: its name, its level, the figure measured, the threshold, the advice."""

Verdict = VerdictReply
"""The checks of one result; its level is the worst of theirs."""


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


def verdict_of(reply: object) -> Verdict | None:
    """The verdict a reply carries: a record's, or read as its record from a reply's JSON
    object (`verdict`); None for a reply without one. WireError names a verdict that is not
    one."""
    if isinstance(reply, Mapping):
        wire = reply.get("verdict")
        return None if wire is None else from_wire(VerdictReply, wire)
    found = getattr(reply, "verdict", None)
    return found if isinstance(found, VerdictReply) else None


def verdict_lines(verdict: Verdict) -> list[str]:
    """A verdict as lines for a terminal: the level first, then each check."""
    lines = [f"{verdict.level.upper()}: {verdict.what}"]
    for c in verdict.checks:
        line = f"  {c.level:<4}  {c.name}: {c.figure} ({c.threshold})"
        lines.append(line + (f"; {c.advice}" if c.advice else ""))
    return lines
