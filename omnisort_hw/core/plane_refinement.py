"""Corner re-measurement on the board's own plane (Datta et al.'s iterative refinement).

With a first model and the board's pose, the image is resampled onto the board plane, where
the grid is straight and axis-aligned; corners are found there by fitting the edge lines
through each corner over whole squares and mapped back through the same model and pose, so
the model's own error cancels to first order. `intrinsics.calibrate_images` decides, per
image, whether these corners or the plain saddle points are kept.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec


def _edge_line_corners(
    rect: np.ndarray, pts: np.ndarray, half_len: int, gap: int = 2, half_width: int = 4
) -> np.ndarray:
    """Refine corners of a fronto-parallel, axis-aligned checkerboard image.

    For every corner, the vertical and the horizontal edge through it are located row by row
    (column by column) as the centroid of the squared gradient across the edge, over
    `half_len` pixels on each side (skipping `gap` pixels at the saddle), fitted with a
    weighted line, and intersected. Long edges average out the staircase of aliased
    renderings, which a small window around the saddle cannot. Vectorised over all corners.
    """
    img = rect.astype(np.float64)
    gx2 = np.zeros_like(img)
    gy2 = np.zeros_like(img)
    gx2[:, 1:-1] = (0.5 * (img[:, 2:] - img[:, :-2])) ** 2
    gy2[1:-1, :] = (0.5 * (img[2:, :] - img[:-2, :])) ** 2
    along = np.concatenate([np.arange(-half_len, -gap + 1), np.arange(gap, half_len + 1)])
    along = along.astype(float)
    across = np.arange(-half_width, half_width + 1, dtype=float)
    design = np.stack([np.ones_like(along), along], axis=1)
    x0, y0 = pts[:, 0].astype(float).copy(), pts[:, 1].astype(float).copy()
    slope_v = np.zeros(len(pts))
    slope_h = np.zeros(len(pts))

    def line_fit(vals: np.ndarray, weights: np.ndarray) -> np.ndarray:
        ata = np.einsum("mi,km,mj->kij", design, weights, design)
        atb = np.einsum("mi,km,km->ki", design, weights, vals)
        return np.linalg.solve(ata, atb[..., None])[..., 0]

    for _ in range(3):
        rows = y0[:, None] + along[None, :]
        xs = (x0[:, None] + slope_v[:, None] * along[None, :])[..., None] + across
        w_v = map_coordinates(
            gx2, [np.broadcast_to(rows[..., None], xs.shape).ravel(), xs.ravel()], order=1
        ).reshape(xs.shape)
        sum_v = w_v.sum(-1) + 1e-12
        edge_x = (w_v * xs).sum(-1) / sum_v
        cols = x0[:, None] + along[None, :]
        ys = (y0[:, None] + slope_h[:, None] * along[None, :])[..., None] + across
        w_h = map_coordinates(
            gy2, [ys.ravel(), np.broadcast_to(cols[..., None], ys.shape).ravel()], order=1
        ).reshape(ys.shape)
        sum_h = w_h.sum(-1) + 1e-12
        edge_y = (w_h * ys).sum(-1) / sum_h
        a, slope_v = line_fit(edge_x, sum_v).T
        c, slope_h = line_fit(edge_y, sum_h).T
        # x = a + bv (y - y0), y = c + bh (x - x0)
        x_new = (a + slope_v * (c - y0) - slope_v * slope_h * x0) / (1.0 - slope_v * slope_h)
        y0 = c + slope_h * (x_new - x0)
        x0 = x_new
    return np.stack([x0, y0], axis=1)


def refine_on_board_plane(
    gray: np.ndarray,
    board: BoardSpec,
    model: OcamModel,
    pose: np.ndarray,
    px_per_square: int = 60,
    blur_sigma: float = 1.0,
) -> np.ndarray:
    """Corners re-measured on the board's own plane (Datta et al.'s iterative refinement).

    The image is resampled through the current model and pose onto the board plane, where
    the grid is straight and axis-aligned; corners are found there by edge-line fitting and
    mapped back through the same model and pose, so the model's own error cancels to first
    order. Returns (cols*rows, 2) pixels.
    """
    ppm = px_per_square / board.square_mm
    margin = 0.5 * board.square_mm
    width = round((board.cols - 1) * px_per_square + 2 * margin * ppm)
    height = round((board.rows - 1) * px_per_square + 2 * margin * ppm)
    gx, gy = np.meshgrid(np.arange(width) / ppm - margin, np.arange(height) / ppm - margin)
    plane = np.stack([gx, gy, np.zeros_like(gx)], axis=-1) @ pose[:3, :3].T + pose[:3, 3]
    maps = model.ray_to_pixel(plane).astype(np.float32)
    src = cv2.GaussianBlur(gray, (0, 0), blur_sigma) if blur_sigma > 0 else gray
    rect = cv2.remap(src, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR)
    start = (board.object_points()[:, :2] + margin) * ppm
    refined = _edge_line_corners(rect, start, int(0.48 * px_per_square))
    mm = refined / ppm - margin
    pts = np.column_stack([mm, np.zeros(len(mm))]) @ pose[:3, :3].T + pose[:3, 3]
    return model.ray_to_pixel(pts)
