"""The `[registration]` section's keys, declared once (`request_fields.param`): the cell file's
parser (`config.sorting.registration_config`) checks the section against them, and
`register-robot` makes its flags from them. Imports nothing heavy: the CLI reads it at every
start."""

from __future__ import annotations

from dataclasses import dataclass

from omnisort_hw.core.choices import DEFAULT_BOARD, SQUARE_RANGE_MM
from omnisort_hw.request_fields import param

FITS = ("auto", "level", "free")
"""How the floor board's pose is fitted: on a level floor in S, free 6-DOF, or weighed by the
calibration's camera roll/pitch 1-sigma."""


@dataclass(frozen=True)
class RegistrationSettings:
    """`[registration]` as declared, each key once with its type, unit, bounds and help (None:
    not given; the defaults are said in the help)."""

    board: str | None = param(
        None,
        max_chars=16,
        help=f"the floor board's inner corners COLSxROWS (default {DEFAULT_BOARD})",
    )
    square_mm: float | None = param(
        None,
        unit="mm",
        lo=SQUARE_RANGE_MM[0],
        hi=SQUARE_RANGE_MM[1],
        help="the floor board's square size",
        flag="--square",
    )
    offset: tuple[float, ...] | None = param(
        None,
        length=6,
        lo=-1e5,
        hi=1e5,
        help="X,Y,Z,RX,RY,RZ: the board frame in the robot base frame (mm, deg, Z-Y-X)",
    )
    fit: str | None = param(
        None,
        choices=FITS,
        help="the board on a level floor in S, free 6-DOF, or auto: weighed by the "
        "calibration's camera roll/pitch 1-sigma (default auto)",
    )
    camera_height_mm: float | None = param(
        None,
        unit="mm",
        lo=1.0,
        hi=1e5,
        help="the camera's nominal height (default 1200)",
        flag="--camera-height",
    )
