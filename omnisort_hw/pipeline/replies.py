"""The replies of the use cases, typed: what every door shows unchanged (the service's
`result`, the CLI's `--json`, the typed client's return value), declared once here.

Each is a dataclass record (the core's own from `core.records`: a picture's `PictureReply`, a
drift decision's `DecisionSummary`, a located cube's `CubeReply`). The service writes it to
JSON with `wire_records.to_wire` and a client reads it back with `wire_records.from_wire`,
so the fields are checked where a reply is built and where it is read, and neither side names
a key; nothing here loads numpy, so a client reads these types at no start-up cost. A record
the reply carries as it was stored or measured (an image record, a calibration file's
`robot_base`, a capture's record, the model's coefficients) stays a `Record`: its own module
declares it. `tests/service/test_door_agreement.py` holds each real reply to its record.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

from omnisort_hw.core.records import (
    BoardCheckReply,
    CrossValidation,
    CubeReply,
    DecisionSummary,
    LaserLineReply,
    PictureReply,
    PointSigmaReply,
    ProjectionSigma,
    Record,
    RejectedBlob,
    RejectedImage,
    SegmentReply,
)
from omnisort_hw.wire_records import absent, wire_key

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


@dataclass(frozen=True, kw_only=True)
class MapSummary:
    """A laser map's counts and segments, its points' sigmas in brief and whether the image
    showed a laser line; with `points` asked, every point on the plane (S, 0.1 mm) and, in the
    same order, its pixel and its sigmas along the surface normal, along the line and off the
    plane (mm)."""

    points: int
    points_on_plane: int
    echoes_dropped: int
    stripe_ends_dropped: int
    segments: list[SegmentReply]
    sigma: PointSigmaReply | None = absent()
    laser_line: LaserLineReply | None = absent()
    points_S: list[list[float]] | None = absent()
    pixels: list[list[float]] | None = absent()
    sigma_normal_mm: list[float] | None = absent()
    sigma_along_mm: list[float] | None = absent()
    sigma_off_plane_mm: list[float] | None = absent()


@dataclass(frozen=True, kw_only=True)
class MapReply(MapSummary, PictureReply):
    """`map`: the map of one image (its record: path and sha256, or the capture), its verdict
    and its picture."""

    image: Record
    verdict: VerdictReply


@dataclass(frozen=True, kw_only=True)
class LocateReply(PictureReply):
    """The cubes found (of the request's colours), their count, the blobs of a cube's colour
    inside the search region that were not taken and why, the verdict, and the picture."""

    cubes: list[CubeReply]
    count: int
    rejected: list[RejectedBlob]
    verdict: VerdictReply


@dataclass(frozen=True, kw_only=True)
class RegisterReply(PictureReply):
    """`register_robot`: the `robot_base` record (as system.json stores it), where it was saved
    (None: not saved), the verdict and the picture."""

    robot_base: Record
    path: str | None
    verdict: VerdictReply


@dataclass(frozen=True, kw_only=True)
class IntrinsicsReply:
    """The intrinsic calibration: camera.json and its report; what camera.json records beside
    the model (the fit per image, the board, the outer band's coverage, the cross-validation,
    the projection uncertainty, the views given twice); the fit's figures; the verdict."""

    path: str
    report: str
    rms_px: float
    per_image_rms_px: dict[str, float]
    images_used: int
    images_rejected: list[RejectedImage]
    corners_rejected: int
    corner_refinement: dict[str, str]  # per image: the refinement its corners got
    std: Record
    poly_degree: int
    board: Record
    coverage: Record
    cross_validation: CrossValidation
    projection_uncertainty: ProjectionSigma
    repeated_views: list[Record]
    created: str
    outer_band_covered: float | None
    center_uv: list[float]
    model: Record
    field_of_view_deg: dict[str, float | None]
    verdict: VerdictReply
    uncertainty_png: str | None = absent()
    repeated_views_warning: str | None = absent()
    images_folder: str | None = absent()
    camera_serial: str | None = absent()  # the service's: the camera it was stored for


@dataclass(frozen=True, kw_only=True)
class ExtrinsicsReply(PictureReply):
    """`calibrate what=extrinsics`: system.json's path, the method and the target, the fitted
    parameters (deg, mm) and their 1-sigmas, the fit's residuals, the image's record, the tone
    curve it was located with, the separation checked against the image's own scale (or why
    not: `not_checked`), the verdict and the picture."""

    path: str
    method: str
    target: str
    parameters: dict[str, float]
    std: dict[str, float]
    residuals: Record
    image: Record | None
    tone_curve: str
    scale_check: Record
    verdict: VerdictReply


@dataclass(frozen=True, kw_only=True)
class DriftReply(DecisionSummary):
    """`check`: the drift decision, when and on what image, for which calibration, the floor
    board against its prediction (or why not measured), whether this image became the
    reference of the finer check, and the verdict."""

    checked_at: str
    image: str
    calibration_key: str
    board: BoardCheckReply | None
    verdict: VerdictReply
    board_problem: str | None = absent()
    reference_adopted: bool = absent(False)


@dataclass(kw_only=True)
class SortExtras:
    """What a sorting run adds to its report as it goes: timings, the cycle, the scene checks,
    the capture, and a verifier's truth (on the simulated cell)."""

    timings_s: dict[str, float] | None = absent()
    cycle: Record | None = absent()
    checks: list[Record] | None = absent()
    capture: Record | None = absent()
    errors_B_mm: list[float] | None = absent()
    collision_events: list[Record] | None = absent()


@dataclass
class CubeOutcome:
    """What happened to one located cube: where it was (mm, NaN where unknown), its status
    ("sorted": placed; "skipped": refused before motion; "failed"; "missed": a verifier's cube
    never located) and why, its bin, its pick's planned motion (its lower bound), and a
    verifier's truth."""

    index: int
    color: str
    center_S_mm: list[float]
    center_B_mm: list[float]
    yaw_B_deg: float
    sigma_mm: float
    status: str
    reason: str = ""
    bin: str | None = None
    planned_motion_s: float = 0.0
    error_mm: float | None = absent()  # filled by a verifier
    in_right_bin: bool | None = absent()  # filled by a verifier
    relocated: bool = absent(False)  # moved after the first capture; located again by a check


@dataclass(frozen=True, kw_only=True)
class SortTotals:
    """A sorting run's counts, its planned motion (in all, and per pick: None without one),
    its wall time; with a verifier, the cubes in their bin, the mean position error and the
    collisions."""

    cubes: int
    sorted: int
    skipped: int
    failed: int
    planned_motion_s: float
    planned_motion_s_per_pick: float | None
    wall_s: float
    sorted_ok: int | None = absent()
    mean_position_error_mm: float | None = absent()
    collisions: int | None = absent()


@dataclass(kw_only=True)
class SortReply(SortExtras):
    """`sort`: each located cube's outcome, the totals, the registration used, the blobs of a
    cube's colour not taken, the verdict, and what the run added."""

    cubes: list[CubeOutcome]
    totals: SortTotals
    registration: Record | None
    rejected_blobs: int
    verdict: VerdictReply


@dataclass(frozen=True)
class AdoptedFile:
    """A calibration file taken in: where from, where it is stored, its new checksum."""

    path: str
    checksum: str
    source: str = wire_key("from")  # a field with no default, sent as `from`


@dataclass(frozen=True)
class AdoptReply:
    """`adopt`: each file taken in, by kind (`camera`, `system`), and whether a drift
    reference was taken with them."""

    adopted: dict[str, AdoptedFile]
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


@dataclass(frozen=True)
class StopReply:
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


@dataclass(frozen=True)
class LaserReply:
    """`laser`: the switch's state as read back after any switching."""

    on: bool


@dataclass(frozen=True)
class CaptureReply:
    """`capture`: one frame, as a file under the capture folder or inline as base64."""

    sequence: int
    wall_time: str
    width: int
    height: int
    format: str
    bytes: int
    path: str | None = absent()
    base64: str | None = absent()


@dataclass(frozen=True)
class AcknowledgeReply:
    """`acknowledge_drift`: whether a drift was there to accept, and that drift."""

    acknowledged: bool
    drift: Record | None


@dataclass(frozen=True)
class CommandDescription:
    """A command as `describe` gives it: how it runs (`quick`, `job`, `safety`...), whether it
    needs the operator's token off loopback, the state a job puts the cell in, its help and
    its arguments' JSON Schema (draft 2020-12)."""

    kind: str
    needs_token: bool
    job_state: str | None
    help: str
    args: Record


@dataclass(frozen=True)
class DescribeReply:
    """`describe`: the schemas' dialect and every command by name."""

    schema_dialect: str
    commands: dict[str, CommandDescription]


@dataclass(frozen=True)
class MoveReply:
    """`move`: the joints (deg) and the TCP pose (4x4, mm) the arm reached."""

    joints_deg: list[float]
    tcp_pose: list[list[float]]


@dataclass(frozen=True)
class DeviceError:
    """A device that could not be connected: its error's message and typed code."""

    error: str
    code: str


@dataclass(frozen=True)
class ArmSafety:
    """The arm's safety after a stop: its robot mode, and whether it may move."""

    robot_mode: str
    ok: bool


@dataclass(frozen=True, kw_only=True)
class ResetReply:
    """`reset`: the state left and the state now (idle), the devices connected again and the
    ones still lost, and the arm's safety (None: no arm connected)."""

    state: str
    previous: str
    reconnected: list[str]
    lost: dict[str, DeviceError]
    arm: ArmSafety | None


@dataclass(frozen=True)
class ShutdownReply:
    """`shutdown`: the service is stopping."""

    shutting_down: bool
