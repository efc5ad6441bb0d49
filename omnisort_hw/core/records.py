"""The core's results that travel in replies, as TypedDicts: a picture written (or why not)
and a drift decision. They import nothing, so a client of the service reads the replies'
types (`pipeline.replies`) without loading numpy or OpenCV."""

from typing import Any, TypedDict

Record = dict[str, Any]
"""A record a reply carries as its own module wrote it (an image's path and sha256, a
capture, a device's health)."""


class PictureReply(TypedDict, total=False):
    """The picture of what a command found: where it was written (None when it was not), and
    why not."""

    overlay_png: str | None
    overlay_problem: str


class DecisionSummary(TypedDict):
    """A drift decision as replies carry it: the turn measured, its threshold, its statistics."""

    drift: bool
    angle_deg: float
    rotvec_deg: list[float]
    std_deg: list[float]
    threshold_deg: float
    t2: float
    p_value: float
    source: str


class LaserLineReply(TypedDict):
    """Whether an image showed a laser line (`core.laser_presence`): the longest thin chain
    against what a line needs, and the pieces that were not one."""

    present: bool
    longest_line_px: float
    min_line_px: float
    chains: int
    spots: int
    blobs: int
    points: int
