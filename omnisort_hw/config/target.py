"""The calibration target's kinds and the checks of its measured dimensions, shared by the
cell file's `[target]`, the CLI and the service: the wall distance sets the scale of every
extrinsic result, so it has no default and no unit guessing."""

from __future__ import annotations

import math
from typing import Any

TARGETS = ("two-sided", "three-sided", "checkerboards")
METHODS_FOR = {
    "two-sided": ("joint", "paper"),
    "three-sided": ("joint", "method1"),
    "checkerboards": ("method2",),
}
SEPARATION_RANGE_MM = (100.0, 10000.0)
"""Inner wall distances a wall target can have, mm: a value below is a typo or metres."""


def separation_problem(value: Any) -> str | None:
    """What is wrong with a measured inner wall distance `value` (mm), or None. The distance
    sets the scale of every extrinsic result, so there is no default and no unit guessing."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return f"expected a number of millimetres, got {value!r}"
    lo, hi = SEPARATION_RANGE_MM
    if 0 < value < 10:
        return (
            f"{value:g} looks like metres; give the inner distance between the walls in mm "
            f"(e.g. {value * 1000:g})"
        )
    if not lo <= value <= hi:
        return f"{value:g} mm is outside the plausible {lo:g}-{hi:g} mm of a wall target"
    return None
