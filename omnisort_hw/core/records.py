"""The core's results that travel in replies: a picture written (or why not), a drift
decision, a laser line's presence, and a located cube (a record, read and written by
`wire_records`). They import nothing numerical, so a client of the service reads the replies'
types (`pipeline.replies`) without loading numpy or OpenCV."""

from dataclasses import dataclass
from typing import Any

from omnisort_hw.wire_records import absent

Record = dict[str, Any]
"""A record a reply carries as its own module wrote it (an image's path and sha256, a
capture, a device's health)."""


@dataclass(frozen=True, kw_only=True)
class PictureReply:
    """The picture of what a command found: where it was written, or why it was not (then no
    path). A reply with a picture is one of these (its fields are the reply's own); neither
    key is sent when no picture was asked."""

    overlay_png: str | None = absent()
    overlay_problem: str | None = absent()


@dataclass(frozen=True, kw_only=True)
class DecisionSummary:
    """A drift decision as replies carry it: the turn measured, its threshold, its statistics."""

    drift: bool
    angle_deg: float
    rotvec_deg: list[float]
    std_deg: list[float]
    threshold_deg: float
    t2: float
    p_value: float
    source: str


@dataclass(frozen=True)
class LaserLineReply:
    """Whether an image showed a laser line (`core.laser_presence`): the longest thin chain
    against what a line needs, and the pieces that were not one."""

    present: bool
    longest_line_px: float
    min_line_px: float
    chains: int
    spots: int
    blobs: int
    points: int


@dataclass(frozen=True)
class SegmentReply:
    """A straight piece of a laser map: its points, its distance from the camera's axis (the
    nearest and the mean, mm), its length, its bearing about the vertical, its ends in S."""

    points: int
    distance_mm: float
    mean_distance_mm: float
    length_mm: float
    bearing_deg: float
    start_S_mm: list[float]
    end_S_mm: list[float]


@dataclass(frozen=True)
class PointSigmaReply:
    """A map's point uncertainties in brief: what they count, and (when any is finite) the
    median and largest sigma along the surface normal and the median pixel noise."""

    sources: list[str]
    normal_mm_median: float | None = absent()
    normal_mm_max: float | None = absent()
    pixel_sigma_px_median: float | None = absent()


@dataclass(frozen=True)
class CubeReply:
    """A located cube: its colour, its centre in S and B (mm) and its yaw about the vertical
    (deg, modulo 90 in (-45, 45]), their 1-sigmas (`sigma_xy_B_mm` with every known source,
    `sigma_fit_xy_B_mm` the outline fit's own; `sigma_mm` radial), the fit's RMS and what it
    used; with its pixels for a client's overlay when the location drew them (its centre and
    its 95 % position ellipse, enlarged `ellipse_scale` times)."""

    color: str
    center_S_mm: list[float]
    center_B_mm: list[float]
    yaw_S_deg: float
    yaw_B_deg: float
    sigma_mm: float
    sigma_xy_B_mm: list[float]
    sigma_fit_xy_B_mm: list[float]
    sigma_yaw_deg: float
    rms_px: float
    area_px: int
    outline_points: int
    laser_points: int
    notes: list[str]
    center_px: list[float] | None = absent()
    ellipse_px: list[list[float]] | None = absent()
    ellipse_scale: float | None = absent()


@dataclass(frozen=True)
class RejectedBlob:
    """A blob of a cube's colour that was not taken for a cube: where, how big, and why."""

    color: str
    area_px: int
    at_S_mm: list[float]
    reason: str


@dataclass(frozen=True)
class RejectedImage:
    """An image a calibration did not use, and why."""

    file: str
    reason: str


@dataclass(frozen=True)
class CrossValidation:
    """An intrinsic calibration's held-out reprojection error: how the views were split, the
    pooled RMS over the held-out corners (None: too few views) against the in-sample RMS, and
    each view's."""

    scheme: str
    rms_px: float | None
    in_sample_rms_px: float | None = absent()
    per_view_rms_px: dict[str, float] | None = absent()


@dataclass(frozen=True)
class BoardCheckReply:
    """The floor board in a drift check against the stored calibration's prediction: its
    corners and those visible, their residuals (px; None without any), and the robot base's
    shift it implies (mm; None where not finite)."""

    corners: int
    visible: int
    residual_px_median: float | None
    residual_px_max: float | None
    base_shift_mm: float | None
    base_shift_xyz_mm: list[float | None]


@dataclass(frozen=True)
class ProjectionSigma:
    """An intrinsic calibration's projection uncertainty as camera.json records it: what it is,
    how the board poses were treated, the median sigma (px) at each angle off the axis (by the
    angle in degrees; None where no view reached), and the largest in view."""

    what: str
    board_poses: str
    median_px_at_angle_deg: dict[str, float | None]
    max_px_in_view: float
