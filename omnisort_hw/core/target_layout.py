"""A wall target as its builder measured it: separation, border heights, each marker's centre
and size per wall (the record `config.target.load_target_description` fills from a TOML file).

Coordinates are the target's own, in millimetres, the same on every wall:

- side walls ("left", "right"): `along_mm` from the walls' near end (towards the boom) along
  +Y, `height_mm` above the wall's foot (where it stands on the floor);
- far wall ("far", three-sided target): `along_mm` from the left wall's inner face along +X.

Markers are named as in `features.MARKER_NAMES` (border_near, border_far, floor_near,
floor_far); for the far wall "near" is its left end. `size_mm` is (along, up).

Without a layout the methods assume the symmetric paper target: the markers of one wall
mirror those of the other (equal positions along the walls and equal heights), positions
unknown, and one border height. A layout replaces that assumption with the measurements.

The functions here turn a layout and a pose of the target into the markers' 3D centres and
outlines in S, and the outline into the centroid of its image (a blob's centroid is not the
image of its centre: a 50 mm marker at 1 m is imaged up to half a pixel off its centre).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from omnisort_hw.core.camera_model import OcamModel

SIDE_WALLS = ("left", "right")
_OUTLINE_STEPS = 12  # points per rectangle side when its image is integrated


@dataclass(frozen=True)
class MarkerSpec:
    """One marker's measured centre (along the wall, above the foot) and size (along, up)."""

    along_mm: float
    height_mm: float
    size_mm: tuple[float, float] | None = None


@dataclass(frozen=True)
class WallSpec:
    """One wall: its border's height above its foot and its markers by name."""

    border_height_mm: float
    markers: dict[str, MarkerSpec] = field(default_factory=dict)


@dataclass(frozen=True)
class TargetLayout:
    """The measured target: kind, inner separation of the side walls, walls by name."""

    kind: str
    separation_mm: float
    walls: dict[str, WallSpec]
    source: str = "target description"

    def border_offset_mm(self, wall: str) -> float:
        """Height of `wall`'s border above the left wall's border (0 for one border height)."""
        return self.walls[wall].border_height_mm - self.walls["left"].border_height_mm

    def marker_offsets(self, keys: list[tuple[str, str]]) -> np.ndarray:
        """(K, 2) per (wall, marker name): along_mm and height above the left border (mm)."""
        left = self.walls["left"].border_height_mm
        return np.array(
            [
                [self.walls[w].markers[n].along_mm, self.walls[w].markers[n].height_mm - left]
                for w, n in keys
            ],
            float,
        )

    def marker_sizes(self, keys: list[tuple[str, str]]) -> np.ndarray | None:
        """(K, 2) sizes (along, up) per key, or None when any marker has no size."""
        sizes = [self.walls[w].markers[n].size_mm for w, n in keys]
        if any(s is None for s in sizes):
            return None
        return np.array(sizes, float)


def side_marker_centres(
    keys: list[tuple[str, str]],
    offsets: np.ndarray,
    x_walls: dict[str, float],
    y0: float,
    z_border: float,
) -> np.ndarray:
    """(K, 3) centres in S of side-wall markers: X of their wall, Y = y0 + along, Z = the left
    border's height + their height above it."""
    xs = np.array([x_walls[w] for w, _ in keys])
    return np.stack([xs, y0 + offsets[:, 0], z_border + offsets[:, 1]], axis=1)


def _outline(centres: np.ndarray, sizes: np.ndarray, along_axis: np.ndarray) -> np.ndarray:
    """(K, 4 * steps, 3) outlines of rectangles on vertical walls, each along S axis
    `along_axis` (1: a side wall X = const, along Y; 0: the far wall Y = const, along X)."""
    t = np.linspace(-0.5, 0.5, _OUTLINE_STEPS, endpoint=False)
    one = np.ones_like(t)
    # counter-clockwise in (along, up): bottom, right, top, left sides
    unit = np.concatenate(
        [
            np.stack([t, -0.5 * one], 1),
            np.stack([0.5 * one, t], 1),
            np.stack([-t, 0.5 * one], 1),
            np.stack([-0.5 * one, -t], 1),
        ]
    )
    pts = np.repeat(centres[:, None, :], unit.shape[0], axis=1)
    rows = np.arange(centres.shape[0])
    pts[rows, :, along_axis] += unit[None, :, 0] * sizes[:, None, 0]
    pts[..., 2] += unit[None, :, 1] * sizes[:, None, 1]
    return pts


def image_centroid_shift(
    model: OcamModel,
    R_SC: np.ndarray,
    centres: np.ndarray,
    sizes: np.ndarray,
    along_axis: np.ndarray | None = None,
    reference: np.ndarray | None = None,
) -> np.ndarray:
    """(K, 2) pixels from the image of each marker's centre to the centroid of its imaged
    rectangle (what a blob's centroid measures), for the camera rotation R_SC; `along_axis`
    per marker as in `_outline` (default: side walls); `reference`: the points whose images
    the shift is from, when the rectangles given are the visible parts of the markers."""
    axis = np.ones(len(centres), int) if along_axis is None else np.asarray(along_axis, int)
    outline = _outline(centres, sizes, axis)
    k, m, _ = outline.shape
    rays = outline.reshape(-1, 3) @ R_SC  # rows: R^T p, in C
    uv = model.ray_to_pixel(rays / np.linalg.norm(rays, axis=1, keepdims=True)).reshape(k, m, 2)
    x, y = uv[..., 0], uv[..., 1]
    x1, y1 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cross = x * y1 - x1 * y
    area = 0.5 * cross.sum(axis=1)
    cx = ((x + x1) * cross).sum(axis=1) / (6.0 * area)
    cy = ((y + y1) * cross).sum(axis=1) / (6.0 * area)
    c_rays = (centres if reference is None else reference) @ R_SC
    centre_uv = model.ray_to_pixel(c_rays / np.linalg.norm(c_rays, axis=1, keepdims=True))
    return np.stack([cx, cy], axis=1) - centre_uv
