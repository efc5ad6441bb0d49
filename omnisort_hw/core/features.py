"""Records of the image features that the extrinsic calibration methods consume.

Extraction (target_features.py) fills them from an image; the simulator can fill them from its
ground truth; the calibration methods read them. Pixels are (u, v), sub-pixel, float.

Walls are named by where they stand in the system frame S: "left" (X < 0, image left),
"right" (X > 0), "far" (the three-sided target's closing wall, at the far end of +Y).
Along a side wall, "near" is the end towards the boom (smaller Y, lower in the image when the
camera looks down) and "far" the other end. Markers: "border_near"/"border_far" sit at the
ends of the black/white border, "floor_near"/"floor_far" near the floor below them.
For the three-sided target the far markers of the side walls stand at the corners where the
side walls meet the far wall.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MARKER_NAMES = ("border_near", "border_far", "floor_near", "floor_far")


@dataclass
class WallFeatures:
    """What one wall of the target shows: its border, its laser line, its markers."""

    border_px: np.ndarray  # (N, 2) points on the black/white border line
    laser_px: np.ndarray  # (M, 2) laser stripe centre points on the white face
    markers_px: dict[str, np.ndarray] = field(default_factory=dict)  # MARKER_NAMES -> (2,)
    floor_px: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # wall/floor line


@dataclass
class TargetFeatures:
    """Features of one image of the two-sided ("two-sided") or U-shaped ("three-sided") target."""

    kind: str
    image_size: tuple[int, int]
    walls: dict[str, WallFeatures]


@dataclass
class BoardFeatures:
    """One vertical checkerboard of the checkerboard method and the laser line across it."""

    name: str  # "left" (along Y, the left of the L) or "far" (along X, across the far end)
    inner_corners: tuple[int, int]  # (cols, rows)
    square_mm: float
    corners_px: np.ndarray  # (cols*rows, 2), row by row as in checkerboard.detect_corners
    laser_px: np.ndarray  # (M, 2) laser stripe centre points on the board


@dataclass
class BoardsFeatures:
    """Features of one image of the two perpendicular checkerboards."""

    image_size: tuple[int, int]
    boards: dict[str, BoardFeatures]
