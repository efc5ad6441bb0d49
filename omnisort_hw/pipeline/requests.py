"""What each use case is asked: one request record per use case, its defaults written once here.

The CLI builds them from its flags, the service from a request's arguments; both hand them to
`pipeline.<use case>.run(rig, request)`. A field left None takes the rig's (the cell file's)
value where the rig has one, else the default below.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from omnisort_hw.errors import InputError

if TYPE_CHECKING:
    from omnisort_hw.core.checkerboard import BoardSpec

DEFAULT_BOARD = "9x6"
"""Inner corners COLSxROWS of a checkerboard when none is named (the paper's boards)."""
DEFAULT_SQUARE_MM = 97.0
"""The square of the extrinsic checkerboards target when none is given (the paper's)."""


def board_spec(board: str | None, square_mm: float | None, field: str) -> BoardSpec:
    """The board `board` (COLSxROWS, default 9x6) with squares of `square_mm`; InputError
    naming `field` when either is not a checkerboard. (The CLI reads the defaults above at
    start, so the board's module is imported only here.)"""
    from omnisort_hw.core.checkerboard import BoardSpec

    try:
        return BoardSpec.parse(board or DEFAULT_BOARD, float(square_mm or 0.0))
    except ValueError as exc:
        raise InputError(f"{field}: {exc}") from None


@dataclass(frozen=True)
class IntrinsicsRequest:
    """Calibrate the fisheye intrinsics from checkerboard images."""

    images: tuple[Path, ...]
    square_mm: float
    board: str | None = None
    degree: int | None = None
    refinement: str = "auto"
    folder: str | None = None  # where the images came from, kept in camera.json

    def board_spec(self) -> BoardSpec:
        return board_spec(self.board, self.square_mm, "board/square_mm")


@dataclass(frozen=True)
class ExtrinsicsRequest:
    """Calibrate camera rotation and laser plane from one image of a target (or a capture)."""

    image: str | None = None
    target: str | None = None
    method: str | None = None
    separation_mm: float | None = None
    board: str | None = None
    square_mm: float | None = None

    def board_spec(self) -> BoardSpec:
        """The checkerboards target's boards (9x6 of 97 mm unless given)."""
        return board_spec(self.board, self.square_mm or DEFAULT_SQUARE_MM, "board/square_mm")


@dataclass(frozen=True)
class MapRequest:
    """Map the laser line of an image (or a capture's laser light) onto the laser plane."""

    image: str | None = None
    with_points: bool = False
    picture: bool = False


@dataclass(frozen=True)
class LocateRequest:
    """Locate the cubes of an image (with a laser-on image, or a capture)."""

    image: str | None = None
    laser_image: str | None = None
    colors: tuple[str, ...] | None = None


@dataclass(frozen=True)
class RegisterRequest:
    """Register the robot base from the floor checkerboard of an image (or a capture)."""

    image: str | None = None
    save: bool = True
    model: str | None = None  # the arm's model, kept in the record


@dataclass(frozen=True)
class SortRequest:
    """Sort the cubes: all, or `max_objects`, or those of `colors`; `register` registers the
    robot base from the floor board of the first capture."""

    max_objects: int | None = None
    colors: tuple[str, ...] | None = None
    register: bool = False

    def __post_init__(self) -> None:
        if self.max_objects is not None and self.max_objects < 1:
            raise InputError(f"max_objects must be at least 1, got {self.max_objects}")
