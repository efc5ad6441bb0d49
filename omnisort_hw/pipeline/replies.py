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

from typing import Any, Literal, NotRequired, TypedDict

from omnisort_hw.core.records import DecisionSummary, LaserLineReply, PictureReply, Record

Level = Literal["pass", "warn", "fail"]


class CheckReply(TypedDict):
    """One criterion of a verdict: its figure against its threshold, and what to do."""

    name: str
    level: Level
    figure: str
    threshold: str
    advice: NotRequired[str]


class VerdictReply(TypedDict):
    """A result's verdict: the worst level of its checks."""

    level: Level
    what: str
    checks: list[CheckReply]


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
    verdict: VerdictReply


class LocateReply(PictureReply):
    cubes: list[Record]
    count: int
    rejected: list[Record]
    verdict: VerdictReply


class RegisterReply(PictureReply):
    robot_base: Record
    path: str | None
    verdict: VerdictReply


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
    verdict: VerdictReply


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
    verdict: VerdictReply


class DriftReply(DecisionSummary):
    checked_at: str
    image: str
    calibration_key: str
    board: Record | None
    board_problem: NotRequired[str]
    reference_adopted: NotRequired[bool]
    verdict: VerdictReply


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
    verdict: VerdictReply


class AdoptReply(TypedDict):
    adopted: dict[str, Record]
    drift_reference: bool


class LayerReply(TypedDict):
    """One detected feature's pixels in the frame, its kind and the colour it is drawn in."""

    name: str
    kind: str
    colour: str
    pixels: list[list[float]]
    labels: NotRequired[list[str]]


class ImageReply(TypedDict):
    """A picture sent to a client: JPEG in base64, its size, and its px per camera px."""

    width: int
    height: int
    scale: float
    format: str
    base64: str


class ViewReply(ImageReply):
    """`view`: a live picture, with its frame's number and wall time."""

    sequence: int
    wall_time: str


class PictureFileReply(ImageReply):
    """`picture`: a PNG this service wrote, as a picture for a screen."""

    path: str


class StopReply(TypedDict):
    """`stop` and `estop`: the job they ended (None: none ran), the state after, and the
    problems met stopping the devices."""

    stopped_job: str | None
    state: str
    problems: list[str]


class DetectReply(TypedDict):
    """A calibration pattern in one frame: its layers, or why it was not found."""

    what: str
    pattern: str
    found: bool
    summary: str
    image_width: int
    image_height: int
    layers: list[LayerReply]
    problem: NotRequired[str]
    picture: NotRequired[ImageReply]


class KeptViewReply(TypedDict):
    """One view kept for the intrinsics: its name, when it was taken, the board's outline."""

    name: str
    taken: str
    outline_px: list[list[float]]


class CoverageReply(TypedDict):
    """The views' corners over the image circle's outer band: which of its sectors (equal
    angles from -180 deg, about `centre_px`) hold a corner, and which lie inside the frame."""

    centre_px: list[float]
    radius_px: float
    outer_band: float
    covered: list[bool]
    inside: list[bool]
    fraction: float


class ViewsReply(TypedDict):
    """The views kept for the intrinsics (`calibrate what=intrinsics folder=<folder>`)."""

    folder: str
    count: int
    need: int
    views: list[KeptViewReply]
    verdict: VerdictReply
    board: NotRequired[str]
    image_width: NotRequired[int]
    image_height: NotRequired[int]
    coverage: NotRequired[CoverageReply]
    added: NotRequired[str]
    removed: NotRequired[list[str]]


class VersionReply(TypedDict):
    """One kept version of a calibration file: its figures, or why it does not verify."""

    path: str
    current: bool
    saved: NotRequired[str]
    checksum: NotRequired[str]
    summary: NotRequired[str]
    problem: NotRequired[str]


class LaserPlaneReply(TypedDict):
    normal: list[float]
    distance_mm: float
    corners_S_mm: list[list[float]]  # a patch of the plane around the emitter, for a picture


class BinReply(TypedDict):
    color: str
    corners_S_mm: list[list[float]]  # the rim's four corners, in order
    floor_S_mm: list[list[float]]  # the same corners on the floor


class ArmReply(TypedDict):
    model: str
    joints_deg: list[float]
    points_S_mm: list[list[float]]  # the base, then each DH frame's origin to the flange


class GeometryReply(TypedDict):
    """The cell in 3D, in S (mm): what is calibrated, each part None until it is."""

    camera_R_SC: list[list[float]] | None
    laser_plane: LaserPlaneReply | None
    robot_base_T_SB: list[list[float]] | None
    arm: ArmReply | None
    bins: list[BinReply]
    cube_size_mm: float  # of `[sorting]`: the cubes a locate finds
    floor_z_mm: float | None  # the robot base's plane (the floor it stands on)
    problems: list[str]  # why a part is missing


class HistoryReply(TypedDict):
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
