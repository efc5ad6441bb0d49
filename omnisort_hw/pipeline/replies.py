"""The replies of the use cases, typed: what every door shows unchanged (the service's
`result`, the CLI's `--json`, the typed client's return value), declared once here.

Each is a `TypedDict` (the core's own from `core.records`: a picture's `PictureReply`, a
drift decision's `DecisionSummary`), so a reply stays plain JSON on the wire while its keys
and their types are checked where it is built and where it is read; nothing here loads numpy,
so a client reads these types at no start-up cost. A record the reply carries as it was
stored or measured (an image record, a calibration file's `robot_base`, a capture's record)
stays a `Record`: its own module declares it. (No postponed annotations here: a TypedDict
reads `NotRequired` when its class is made, and `tests/service/test_door_agreement.py` holds
each real reply against its declared keys.)
"""

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, NotRequired, TypedDict

from omnisort_hw.core.records import DecisionSummary, LaserLineReply, PictureReply, Record
from omnisort_hw.wire_records import absent

Level = Literal["pass", "warn", "fail"]


_RANK: dict[str, int] = {"pass": 0, "warn": 1, "fail": 2}


def worst(levels: Sequence[Level]) -> Level:
    """The worst of some levels (pass when none)."""
    rank = max((_RANK[lv] for lv in levels), default=0)
    levels_by_rank: tuple[Level, ...] = ("pass", "warn", "fail")
    return levels_by_rank[rank]


@dataclass(frozen=True)
class CheckReply:
    """One criterion of a verdict: its figure against its threshold, and what to do (none on
    a pass: the key is left out)."""

    name: str
    level: Level
    figure: str
    threshold: str
    advice: str = absent("")


@dataclass(frozen=True)
class VerdictReply:
    """A result's verdict: its checks, and its level, the worst of theirs (computed, so a
    verdict read from a reply cannot disagree with its checks)."""

    what: str
    checks: tuple[CheckReply, ...]
    level: Level = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "level", worst([c.level for c in self.checks]))


VerdictWire = Record
"""A verdict in a reply not yet a record: `to_wire(VerdictReply)`."""


class MapSummary(TypedDict):
    """A laser map's counts and segments; with `points`, every point and its sigmas."""

    points: int
    points_on_plane: int
    echoes_dropped: int
    stripe_ends_dropped: int
    segments: list[Record]
    sigma: NotRequired[Record]
    laser_line: NotRequired[LaserLineReply]
    points_S: NotRequired[list[list[float]]]
    pixels: NotRequired[list[list[float]]]
    sigma_normal_mm: NotRequired[list[float]]
    sigma_along_mm: NotRequired[list[float]]
    sigma_off_plane_mm: NotRequired[list[float]]


class MapReply(MapSummary, PictureReply):
    image: Record
    verdict: VerdictWire


class LocateReply(PictureReply):
    cubes: list[Record]
    count: int
    rejected: list[Record]
    verdict: VerdictWire


class RegisterReply(PictureReply):
    robot_base: Record
    path: str | None
    verdict: VerdictWire


class IntrinsicsReply(TypedDict):
    """The intrinsic calibration: camera.json and its report; what camera.json records beside
    the model (the fit per image, the board, the outer band's coverage, the cross-validation,
    the projection uncertainty, the views given twice); the fit's figures; the verdict."""

    path: str
    report: str
    uncertainty_png: NotRequired[str]
    rms_px: float
    per_image_rms_px: dict[str, float]
    images_used: int
    images_rejected: list[Record]
    corners_rejected: int
    corner_refinement: str
    std: Record
    poly_degree: int
    board: Record
    coverage: Record
    cross_validation: Record
    projection_uncertainty: Record
    repeated_views: list[Record]
    repeated_views_warning: NotRequired[str]
    images_folder: NotRequired[str]
    camera_serial: NotRequired[str | None]  # the service's: the camera it was stored for
    created: str
    outer_band_covered: float | None
    center_uv: list[float]
    model: Record
    field_of_view_deg: dict[str, float | None]
    verdict: VerdictWire


class ExtrinsicsReply(PictureReply):
    path: str
    method: str
    target: str
    parameters: dict[str, float]
    std: dict[str, float]
    residuals: dict[str, Any]
    image: Record | None
    tone_curve: str
    scale_check: Record
    verdict: VerdictWire


class DriftReply(DecisionSummary):
    checked_at: str
    image: str
    calibration_key: str
    board: Record | None
    board_problem: NotRequired[str]
    reference_adopted: NotRequired[bool]
    verdict: VerdictWire


class SortExtras(TypedDict, total=False):
    """What a sorting run adds to its report: timings, the cycle, the scene checks, the
    capture, and a verifier's truth (on the simulated cell)."""

    timings_s: dict[str, float]
    cycle: Record
    checks: list[Record]
    capture: Record
    errors_B_mm: list[float]
    collision_events: list[Record]


class SortReply(SortExtras):
    cubes: list[Record]
    totals: Record
    registration: Record | None
    rejected_blobs: int
    verdict: VerdictWire


class AdoptReply(TypedDict):
    adopted: dict[str, Record]
    drift_reference: bool


@dataclass(frozen=True)
class LayerReply:
    """One detected feature's pixels in the frame, its kind and the colour it is drawn in
    (`labels`: the markers' names, none for other kinds)."""

    name: str
    kind: str
    colour: str
    pixels: list[list[float]]
    labels: list[str] | None = absent()


@dataclass(frozen=True)
class ImageReply:
    """A picture sent to a client: JPEG in base64, its size, and its px per camera px."""

    width: int
    height: int
    scale: float
    format: str
    base64: str

    @property
    def data_url(self) -> str:
        """The picture for an `<img>`'s source."""
        mime = "jpeg" if self.format == "jpg" else self.format
        return f"data:image/{mime};base64,{self.base64}"


@dataclass(frozen=True)
class ViewReply(ImageReply):
    """`view`: a live picture, with its frame's number and wall time."""

    sequence: int
    wall_time: str


@dataclass(frozen=True)
class PictureFileReply(ImageReply):
    """`picture`: a PNG this service wrote, as a picture for a screen."""

    path: str


class StopReply(TypedDict):
    """`stop` and `estop`: the job they ended (None: none ran), the state after, and the
    problems met stopping the devices."""

    stopped_job: str | None
    state: str
    problems: list[str]


@dataclass(frozen=True)
class DetectReply:
    """A calibration pattern in one frame: its layers, or why it was not found; the frame as a
    picture when the service sends one."""

    what: str
    pattern: str
    found: bool
    summary: str
    image_width: int
    image_height: int
    layers: list[LayerReply]
    problem: str | None = absent()
    picture: ImageReply | None = absent()


@dataclass(frozen=True)
class KeptViewReply:
    """One view kept for the intrinsics: its name, when it was taken, the board's outline."""

    name: str
    taken: str
    outline_px: list[list[float]]


@dataclass(frozen=True)
class CoverageReply:
    """The views' corners over the image circle's outer band: which of its sectors (equal
    angles from -180 deg, about `centre_px`) hold a corner, and which lie inside the frame."""

    centre_px: list[float]
    radius_px: float
    outer_band: float
    covered: list[bool]
    inside: list[bool]
    fraction: float


@dataclass(frozen=True)
class ViewsReply:
    """The views kept for the intrinsics (`calibrate what=intrinsics folder=<folder>`); the
    board, the frame's size and the coverage once a view is kept; what a request added or
    removed."""

    folder: str
    count: int
    need: int
    views: list[KeptViewReply]
    verdict: VerdictReply
    board: str | None = absent()
    image_width: int | None = absent()
    image_height: int | None = absent()
    coverage: CoverageReply | None = absent()
    added: str | None = absent()
    removed: list[str] | None = absent()


@dataclass(frozen=True)
class VersionReply:
    """One kept version of a calibration file: when it was saved, its checksum and a summary,
    or (`problem`) why it does not verify."""

    path: str
    current: bool
    saved: str | None = absent()
    checksum: str | None = absent()
    summary: str | None = absent()
    problem: str | None = absent()


@dataclass(frozen=True)
class LaserPlaneReply:
    """The laser plane in S: its unit normal, its distance below the camera, and a patch of it
    around the emitter (4 corners, in order) for a picture."""

    normal: list[float]
    distance_mm: float
    corners_S_mm: list[list[float]]


@dataclass(frozen=True)
class BinReply:
    """A bin of `[sorting]` in S: its colour, its rim's four corners in order, the same corners
    on the floor."""

    color: str
    corners_S_mm: list[list[float]]
    floor_S_mm: list[list[float]]


@dataclass(frozen=True)
class ArmReply:
    """The arm as it stands: its model, its joints, and the base then each DH frame's origin to
    the flange in S."""

    model: str
    joints_deg: list[float]
    points_S_mm: list[list[float]]


@dataclass(frozen=True)
class GeometryReply:
    """The cell in 3D, in S (mm): what is calibrated, each part None until it is."""

    cube_size_mm: float  # of `[sorting]`: the cubes a locate finds
    camera_R_SC: list[list[float]] | None = None
    laser_plane: LaserPlaneReply | None = None
    robot_base_T_SB: list[list[float]] | None = None
    arm: ArmReply | None = None
    bins: list[BinReply] = field(default_factory=list)
    floor_z_mm: float | None = None  # the robot base's plane (the floor it stands on)
    problems: list[str] = field(default_factory=list)  # why a part is missing


@dataclass(frozen=True)
class HistoryReply:
    """A calibration file's current version and the ones kept before it, newest first."""

    kind: str
    versions: list[VersionReply]


CalibrateReply = IntrinsicsReply | ExtrinsicsReply
"""`calibrate`'s reply: the intrinsics' or the extrinsics', as the request's `what` asks."""


class LaserReply(TypedDict):
    """`laser`: the switch's state as read back after any switching."""

    on: bool


class CaptureReply(TypedDict):
    """`capture`: one frame, as a file under the capture folder or inline as base64."""

    sequence: int
    wall_time: str
    width: int
    height: int
    format: str
    bytes: int
    path: NotRequired[str]
    base64: NotRequired[str]


class AcknowledgeReply(TypedDict):
    """`acknowledge_drift`: whether a drift was there to accept, and that drift."""

    acknowledged: bool
    drift: Record | None
