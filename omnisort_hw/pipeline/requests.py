"""What each command is asked: one request record per command, the one declaration of its
arguments (type, unit, bounds, choices, default, help and the rules between them, through
`request_fields.param`).

The protocol's checks, its `describe` schema and the CLI's flags are made from these records;
the doors hand them to `pipeline.<use case>.run(rig, request)`. A field left None takes the
rig's (the cell file's) value where the rig has one, else the default below.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

from omnisort_hw.core.choices import (
    DEFAULT_BOARD,
    METHODS,
    REFINEMENTS,
    SQUARE_RANGE_MM,
    TARGETS,
)
from omnisort_hw.errors import InputError
from omnisort_hw.request_fields import GIVEN, param

if TYPE_CHECKING:
    from omnisort_hw.core.checkerboard import BoardSpec

DETECT_PATTERNS = ("target", "board", "floor")
VIEW_ACTIONS = ("list", "add", "remove", "clear")
DEFAULT_SQUARE_MM = 97.0
"""The square of the extrinsic checkerboards target when none is given (the paper's)."""

IMAGE_HELP = "image file (over the protocol: an absolute path on the cell PC); omitted: a capture"
LASER_OFF_HELP = "laser-off image file (over the protocol: an absolute path); omitted: a capture"
COLORS_HELP = "only these colours (names of the colour table)"


def board_spec(board: str | None, square_mm: float | None, field: str) -> BoardSpec:
    """The board `board` (COLSxROWS, default 9x6) with squares of `square_mm`; InputError
    naming `field` when either is not a checkerboard. (The CLI reads the defaults above at
    start, so the board's module is imported only here.)"""
    from omnisort_hw.core.checkerboard import BoardSpec

    try:
        return BoardSpec.parse(board or DEFAULT_BOARD, float(square_mm or 0.0))
    except ValueError as exc:
        raise InputError(f"{field}: {exc}") from None


def _width_px() -> Any:
    """The `width` of a picture sent to a client: scaled down to it, never enlarged."""
    return param(960, lo=64, hi=4096, unit="px", help="the picture's width at most")


def _quality(default: int) -> Any:
    """The JPEG quality of a picture sent to a client."""
    return param(default, lo=10, hi=95, help="JPEG quality")


def _board(only_when: tuple[Any, ...]) -> Any:
    """The `board` argument: a checkerboard's inner corners (the default's when omitted)."""
    return param(
        None,
        max_chars=16,
        help=f"board inner corners COLSxROWS (default {DEFAULT_BOARD})",
        only_when=only_when,
    )


def _image(help: str = IMAGE_HELP) -> Any:
    """The `image` argument: a path on the cell PC, or a capture when omitted."""
    return param(None, kind="path", help=help, flag="image")


_INTRINSICS = (("what", ("intrinsics",)),)
_EXTRINSICS = (("what", ("extrinsics",)),)


@dataclass(frozen=True)
class CalibrateRequest:
    """Calibrate: intrinsics from a folder of checkerboard images, extrinsics (camera rotation
    and laser plane) from one image of a target or a capture."""

    what: str = param(choices=("intrinsics", "extrinsics"), help="which calibration")
    folder: str | None = param(
        None,
        kind="path",
        help="absolute path of the folder of checkerboard images",
        only_when=_INTRINSICS,
        required_when=_INTRINSICS,
    )
    board: str | None = _board((("target", (None, "checkerboards")),))
    square_mm: float | None = param(
        None,
        unit="mm",
        lo=SQUARE_RANGE_MM[0],
        hi=SQUARE_RANGE_MM[1],
        help=f"board square size (extrinsics checkerboards: default {DEFAULT_SQUARE_MM:g})",
        only_when=(("target", (None, "checkerboards")),),
        required_when=_INTRINSICS,
        flag="--square",
    )
    degree: int | None = param(
        None, lo=2, hi=12, help="polynomial degree (default: chosen)", only_when=_INTRINSICS
    )
    refinement: str | None = param(
        None,
        choices=REFINEMENTS,
        help="corner refinement: saddle points, re-measured on the board plane, or per image "
        "whichever agrees better with the first model (default auto)",
        only_when=_INTRINSICS,
    )
    image: str | None = param(
        None, kind="path", help=IMAGE_HELP, only_when=_EXTRINSICS, flag="image"
    )
    target: str | None = param(
        None, choices=TARGETS, help="the calibration target", only_when=_EXTRINSICS
    )
    separation_mm: float | None = param(
        None,
        unit="mm",
        lo=1.0,
        hi=100000.0,
        help="measured inner distance between the walls (default: the cell file's [target])",
        only_when=(*_EXTRINSICS, ("target", (None, "two-sided", "three-sided"))),
        flag="--separation",
    )
    method: str | None = param(
        None,
        choices=METHODS,
        help="calibration method (default: the best one for the target)",
        only_when=_EXTRINSICS,
    )
    target_file: str | None = param(
        None,
        kind="path",
        help="target description TOML (deploy/target.example.toml): the wall target as "
        "measured; default: the symmetric paper target",
        only_when=_EXTRINSICS,
    )

    def intrinsics(self, images: tuple[Path, ...]) -> IntrinsicsRequest:
        """The intrinsics request of these images (the folder's, or the CLI's list)."""
        return IntrinsicsRequest(self, images)

    def board_spec(self) -> BoardSpec:
        """The checkerboard: the intrinsics' views (the square is needed), or the extrinsic
        checkerboards target's (9x6 of 97 mm unless given)."""
        default = DEFAULT_SQUARE_MM if self.what == "extrinsics" else 0.0
        return board_spec(self.board, self.square_mm or default, "board/square_mm")


@dataclass(frozen=True)
class IntrinsicsRequest:
    """A `calibrate what=intrinsics` request with the images it names: its folder's (the
    service), or the command line's list (the CLI). Its arguments are the calibrate request's,
    declared there once."""

    calibrate: CalibrateRequest
    images: tuple[Path, ...]


@dataclass(frozen=True)
class MapRequest:
    """Map the laser line of an image (or a capture's laser light) onto the laser plane."""

    image: str | None = _image()
    points: bool = param(
        False, help="include every laser point on the plane (points_S, mm) and its pixel"
    )
    picture: bool = param(
        False, help="draw the map's picture (the image with its points, and their top view)"
    )


@dataclass(frozen=True)
class LocateRequest:
    """Locate the cubes of an image (with a laser-on image, or a capture): colour, centre and
    yaw in the camera and robot frames."""

    image: str | None = _image(LASER_OFF_HELP)
    laser_image: str | None = param(
        None, kind="path", help="image file of the same view with the laser on"
    )
    colors: tuple[str, ...] | None = param(None, help=COLORS_HELP)


@dataclass(frozen=True)
class RegisterRequest:
    """Register the robot base from the floor checkerboard of an image (or a capture)."""

    image: str | None = _image(LASER_OFF_HELP)
    save: bool = param(True, help="store the robot base in the system calibration")
    model: str | None = param(
        None, max_chars=64, help="the arm's model, kept in the record (UR5e...)"
    )


@dataclass(frozen=True)
class SortRequest:
    """Locate the cubes and put each in the bin of its colour: all, or `max_objects`, or those
    of `colors`."""

    max_objects: int | None = param(
        None, lo=1, hi=1000, help="pick at most this many cubes", flag="--max"
    )
    colors: tuple[str, ...] | None = param(None, help=COLORS_HELP)
    register: bool = param(
        False, help="register the robot base from the floor board of the first capture"
    )


@dataclass(frozen=True)
class CheckRequest:
    """Drift check: a laser-off image (or capture) against the stored calibration's reference."""

    image: str | None = _image(LASER_OFF_HELP)


@dataclass(frozen=True)
class AdoptRequest:
    """Take calibration files made by the CLI as the cell's, each verified against the cell."""

    camera: str | None = param(
        None, kind="path", help="absolute path of a camera.json made by the CLI"
    )
    system: str | None = param(
        None, kind="path", help="absolute path of a system.json made by the CLI"
    )


@dataclass(frozen=True)
class ViewRequest:
    """A live picture for a screen: a fresh frame, scaled down and JPEG-encoded (base64); no
    file written, nothing switched, nothing logged."""

    width: int = _width_px()
    quality: int = _quality(80)


@dataclass(frozen=True)
class DetectRequest:
    """Find a calibration pattern in one fresh frame (or an image file), for a person placing
    it: its pixels and a picture of the same frame. Nothing fitted, saved, switched or logged."""

    what: str = param(
        "target",
        choices=DETECT_PATTERNS,
        help="the extrinsic target, a checkerboard (intrinsics views) or the floor board "
        "of [registration]",
    )
    target: str | None = param(
        None,
        choices=TARGETS,
        help="which target (default: the cell file's [target] kind)",
        only_when=(("what", (None, "target")),),
    )
    board: str | None = _board((("what", (None, "target", "board")),))
    image: str | None = param(
        None,
        kind="path",
        help="image file (over the protocol: an absolute path on the cell PC); omitted: a "
        "live frame, the laser as it is",
        flag="image",
    )
    width: int = _width_px()
    quality: int = _quality(80)


@dataclass(frozen=True)
class ViewsRequest:
    """The intrinsic calibration's views, taken from the live camera: add one (the full board
    must be in it), list them with their coverage of the image circle, remove one, or clear
    them."""

    action: str = param("list", choices=VIEW_ACTIONS, help="what to do with the views")
    board: str | None = _board((("action", ("add",)),))
    name: str | None = param(
        None,
        max_chars=32,
        help="the view to remove (view_001...)",
        only_when=(("action", ("remove",)),),
        required_when=(("action", ("remove",)),),
    )


@dataclass(frozen=True)
class HistoryRequest:
    """A calibration file's current version and the versions kept before it (go back to one
    with `adopt`)."""

    kind: str = param("system", choices=("camera", "system"), help="which calibration file")


@dataclass(frozen=True)
class GeometryRequest:
    """The cell in 3D, in S (mm), for a picture of it: the camera, the laser plane, the robot
    base, the arm's links as it stands, the bins and the floor. Read-only: nothing is grabbed,
    moved or written."""


@dataclass(frozen=True)
class PictureRequest:
    """A picture the service wrote (a reply's `overlay_png`), scaled down and JPEG-encoded
    (base64), for a client on another machine or under another user."""

    path: str = param(
        kind="path", help="absolute path of a picture the service wrote (a reply's overlay_png)"
    )
    width: int = _width_px()
    quality: int = _quality(85)


@dataclass(frozen=True)
class CaptureRequest:
    """Grab one image; returned as a file path or base64."""

    encoding: str = param("path", choices=("path", "base64"), help="a file path, or base64")
    format: str = param("png", choices=("png", "jpg"), help="image file format")
    laser: bool | None = param(None, help="switch the laser to this state before grabbing")


@dataclass(frozen=True)
class LaserRequest:
    """Switch or read the laser line."""

    on: bool | None = param(None, help="true: on, false: off, omitted: read the state")


@dataclass(frozen=True)
class MoveRequest:
    """Move the arm: a joint target in joint space, a Cartesian target in a straight TCP line."""

    EXACTLY_ONE: ClassVar[tuple[str, ...]] = ("joints_deg", "pose", "matrix")

    joints_deg: tuple[float, ...] | None = param(
        None, length=6, lo=-360.0, hi=360.0, unit="deg", help="6 joint angles"
    )
    pose: tuple[float, ...] | None = param(
        None,
        length=6,
        lo=-1e5,
        hi=1e5,
        help="TCP pose [x, y, z mm, rx, ry, rz deg] (rotation vector) in the base frame",
    )
    matrix: tuple[tuple[float, ...], ...] | None = param(
        None, kind="matrix4", lo=-1e5, hi=1e5, unit="mm", help="TCP pose as a 4x4 matrix (rows)"
    )
    speed_deg_s: float | None = param(
        None,
        lo=0.1,
        hi=180.0,
        unit="deg/s",
        help="joint speed (joint targets)",
        only_when=(("joints_deg", GIVEN),),
        why="is for joint targets; use speed_mm_s",
    )
    speed_mm_s: float | None = param(
        None,
        lo=0.1,
        hi=1000.0,
        unit="mm/s",
        help="TCP speed (Cartesian targets)",
        only_when=(("joints_deg", (None,)),),
        why="is for Cartesian targets; use speed_deg_s",
    )


@dataclass(frozen=True)
class ResetRequest:
    """Leave the fault/stopped state when the arm is safe."""

    gripper_empty: bool = param(
        False, help="an operator confirms the gripper's load was removed by hand"
    )
