"""Pictures of the cell's own measurements, in the style of `overlays` (the image, its pixel
coordinates kept, then a legend column; text drawn once with a dark outline): arrays in, BGR
arrays out.

- `draw_registration`: the floor board's corners as found, and the robot base frame B (its
  axes, 300 mm long, projected through the calibration) where the registration put it;
- `draw_cubes`: each located cube's outline (white on black, visible on every cube colour),
  its index, and its 95 % position ellipse on the floor (drawn enlarged, the factor in the
  legend: a millimetre is a pixel or two at the cell's distances).

The verdict's lines (`pipeline.verdict.verdict_lines`) go into the legend, coloured by level.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import cv2
import numpy as np

from omnisort_hw.core.cube_location import Cube
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.overlays import (
    Colour,
    draw_dots,
    draw_polyline,
    legend_panel,
    line_scale,
    project_S,
    put_text,
)
from omnisort_hw.core.records import CubeReply

AXIS_MM = 300.0
AXES: tuple[tuple[str, Colour], ...] = (("X", (0, 0, 255)), ("Y", (0, 200, 0)), ("Z", (255, 80, 0)))
CORNERS: Colour = (255, 0, 255)
FIRST_CORNER: Colour = (0, 0, 255)
ELLIPSE: Colour = (0, 220, 255)
CHI2_95_2D = 5.991  # chi-square of 2 degrees of freedom at 95 %
LEVEL_COLOURS: dict[str, Colour] = {
    "PASS": (80, 220, 80),
    "WARN": (0, 190, 255),
    "FAIL": (60, 60, 255),
}


def _level_colour(line: str) -> Colour | None:
    word = line.strip().split(" ", 1)[0].rstrip(":").upper()
    return LEVEL_COLOURS.get(word)


def _bgr(image: np.ndarray) -> np.ndarray:
    return image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)


def _with_legend(
    left: np.ndarray, lines: Sequence[str], keys: Sequence[tuple[str, Colour]]
) -> np.ndarray:
    scale = 0.45 * line_scale(left)
    coloured = [(text, _level_colour(text)) for text in lines]
    return np.concatenate([left, legend_panel(left.shape[0], coloured, keys, scale)], axis=1)


def draw_registration(
    image: np.ndarray,
    calib: SystemCalibration,
    corners_px: np.ndarray,
    T_SB: np.ndarray,
    lines: Sequence[str],
) -> np.ndarray:
    """The registration's picture: `corners_px` (N, 2) of the floor board (the first in red),
    the base frame B of `T_SB` (4x4, mm) as three projected axes, and the legend `lines`."""
    left = _bgr(image)
    thick = line_scale(left)
    draw_dots(left, corners_px, CORNERS, 2 * thick)
    draw_dots(left, np.asarray(corners_px, float)[:1], FIRST_CORNER, 4 * thick)
    steps = np.linspace(0.0, AXIS_MM, 31)[:, None]
    origin = T_SB[:3, 3]
    for axis, (name, colour) in enumerate(AXES):
        pts = origin + steps * T_SB[:3, axis]
        px = project_S(calib, pts)
        draw_polyline(left, px, (0, 0, 0), 3 * thick + 2)
        draw_polyline(left, px, colour, 3 * thick)
        end = px[-1]
        if np.all(np.isfinite(end)):
            put_text(left, f"{name}_B", (int(end[0]) + 4, int(end[1])), colour, 0.5 * thick)
    keys = [(f"robot base {n} axis ({AXIS_MM:.0f} mm)", c) for n, c in AXES]
    keys.append(("floor board corners (first: red)", CORNERS))
    return _with_legend(left, lines, keys)


ELLIPSE_ENLARGE = 10.0
"""How many times a cube's position ellipse is enlarged where it is drawn (a few mm at a metre
would be a pixel or less)."""


def cube_pixels(calib: SystemCalibration, T_SB: np.ndarray, cube: Cube) -> CubeReply:
    """The cube as a reply gives it, with where it is in the image for a client's overlay:
    its centre and its 95 % position ellipse enlarged `ELLIPSE_ENLARGE` times (25 points), in
    camera pixels."""
    centre = project_S(calib, np.asarray(cube.center_S, float)[None, :])[0]
    ring = ellipse_px(calib, T_SB, cube, ELLIPSE_ENLARGE, points=25)
    return replace(
        cube.summary(),
        center_px=np.round(centre, 1).tolist(),
        ellipse_px=np.round(ring, 1).tolist(),
        ellipse_scale=ELLIPSE_ENLARGE,
    )


def ellipse_px(
    calib: SystemCalibration, T_SB: np.ndarray, cube: Cube, enlarge: float, points: int = 61
) -> np.ndarray:
    """The cube's 95 % position ellipse on its own height in B, enlarged, projected (M, 2)."""
    cov = cube.position_cov_xy
    if cov is None:
        cov = np.diag(np.square(cube.sigma_xy_mm))
    vals, vecs = np.linalg.eigh(np.asarray(cov, float))
    t = np.linspace(0.0, 2.0 * np.pi, points)
    circle = np.stack([np.cos(t), np.sin(t)], axis=1) * np.sqrt(
        np.clip(vals, 0.0, None) * CHI2_95_2D
    )
    xy = cube.center_B[:2] + enlarge * circle @ vecs.T
    pts_B = np.column_stack([xy, np.full(len(xy), cube.center_B[2])])
    pts_S = pts_B @ T_SB[:3, :3].T + T_SB[:3, 3]
    return project_S(calib, pts_S)


def draw_cubes(
    image: np.ndarray,
    calib: SystemCalibration,
    T_SB: np.ndarray,
    cubes: Sequence[Cube],
    lines: Sequence[str],
    enlarge: float = ELLIPSE_ENLARGE,
) -> np.ndarray:
    """The location's picture: each cube's outline, its index (the legend `lines` give its
    colour, position and sigma) and its 95 % position ellipse drawn `enlarge` times its
    size."""
    left = _bgr(image)
    thick = line_scale(left)
    for i, cube in enumerate(cubes):
        if cube.outline_px is not None:
            draw_dots(left, cube.outline_px, (0, 0, 0), thick + 1)
            draw_dots(left, cube.outline_px, (255, 255, 255), max(0, thick - 1))
        ellipse = ellipse_px(calib, T_SB, cube, enlarge)
        draw_polyline(left, ellipse, (0, 0, 0), 2 * thick + 2)
        draw_polyline(left, ellipse, ELLIPSE, 2 * thick)
        x, y = cube.bbox[:2]
        label = str(i)  # the legend gives each cube's colour, position and sigma
        put_text(
            left, label, (int(x), max(12 * thick, int(y) - 6 * thick)), (255, 255, 255), 0.5 * thick
        )
    keys = [
        ("cube outline (white on black)", (255, 255, 255)),
        (f"95 % position ellipse, drawn x{enlarge:g}", ELLIPSE),
    ]
    return _with_legend(left, lines, keys)
