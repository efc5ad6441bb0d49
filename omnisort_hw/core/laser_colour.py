"""A laser of any colour seen as a red one: the stripe extractor (`core.laser_stripe`) and the
laser-light difference (`core.laser_difference`) are tuned and measured on red light, and a
green or blue line laser is found by the same code once the image's channels are reordered.

The laser's channel plays red. Of the other two, the one whose excess makes the common
look-alike surface plays green, since the redness punishes green above blue: for a red laser
yellow and orange (green above blue); for a green one yellow (red above blue); for a blue one
cyan (green above red).
"""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.choices import LASER_COLORS
from omnisort_hw.errors import InputError

# The BGR channel indices that play blue, green and red for each laser colour.
_AS_RED: dict[str, list[int]] = {"red": [0, 1, 2], "green": [0, 2, 1], "blue": [2, 1, 0]}
assert tuple(_AS_RED) == LASER_COLORS


def as_red_laser(bgr: np.ndarray, color: str) -> np.ndarray:
    """`bgr` (..., 3) with its channels reordered so that a `color` laser is seen as a red one
    (the array itself for red); InputError for a colour not in `core.choices.LASER_COLORS`."""
    order = _AS_RED.get(color)
    if order is None:
        raise InputError(f"laser color: {color!r} is not one of {', '.join(LASER_COLORS)}")
    return bgr if color == "red" else np.ascontiguousarray(bgr[..., order])
