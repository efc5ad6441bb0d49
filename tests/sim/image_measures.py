"""Measurements the simulator tests make on rendered images."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np


def redness(image: np.ndarray) -> np.ndarray:
    """Red above the other two channels, in [0, 1]: the laser stripe's signature."""
    f = image.astype(np.float32) / 255.0
    return np.clip(f[..., 2] - np.maximum(f[..., 1], f[..., 0]), 0.0, 1.0)


def stripe_offsets(
    image: np.ndarray, polylines_px: list[dict[str, Any]], every: int = 3, half: float = 6.0
) -> np.ndarray:
    """Signed offsets (px) of the stripe's centre from the truth polylines.

    At every `every`-th polyline point the redness is sampled across the line (bilinear,
    0.25 px steps over +-`half` px) and its intensity-weighted centroid is taken.
    """
    red = redness(image)
    s = np.arange(-half, half + 1e-9, 0.25)
    out = []
    for line in polylines_px:
        pts = np.asarray(line["points_px"], float)
        for i in range(2, len(pts) - 2, every):
            tangent = pts[i + 2] - pts[i - 2]
            tangent /= np.linalg.norm(tangent)
            normal = np.array([-tangent[1], tangent[0]])
            xy = (pts[i] + s[:, None] * normal).astype(np.float32)
            prof = cv2.remap(red, xy[:, :1], xy[:, 1:], cv2.INTER_LINEAR)[:, 0]
            w = np.maximum(prof - 0.03, 0.0)
            if w.sum() > 0.05:
                out.append(float((w * s).sum() / w.sum()))
    return np.array(out)


def corner_errors(found: np.ndarray, truth_px: np.ndarray) -> np.ndarray:
    """Distances (px) between detected and true corners, up to the board's order reversal."""
    direct = np.linalg.norm(found - truth_px, axis=1)
    reverse = np.linalg.norm(found[::-1] - truth_px, axis=1)
    return direct if np.median(direct) <= np.median(reverse) else reverse


def only_board(image: np.ndarray, corners_px: np.ndarray, grow_px: int) -> np.ndarray:
    """The image with everything but the region around one board greyed out (the scene of
    the checkerboard baseline holds two boards of the same size)."""
    mask = np.zeros(image.shape[:2], np.uint8)
    hull = cv2.convexHull(corners_px.astype(np.float32)).astype(np.int32)
    cv2.fillConvexPoly(mask, hull, 255)
    mask = cv2.dilate(mask, np.ones((2 * grow_px + 1, 2 * grow_px + 1), np.uint8))
    out = image.copy()
    out[mask == 0] = 128
    return out


def distance_to_lines(pts: np.ndarray, lines: list[dict]) -> np.ndarray:
    """(N,) distance (px) of each point to the nearest segment of the truth's polylines."""
    segs = np.concatenate(
        [
            np.stack([p[:-1], p[1:]], axis=1)
            for p in (np.asarray(line["points_px"]) for line in lines)
        ]
    )
    a, b = segs[None, :, 0], segs[None, :, 1]
    ab = b - a
    t = np.clip(np.sum((pts[:, None] - a) * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-12), 0, 1)
    return np.min(np.linalg.norm(pts[:, None] - (a + t[..., None] * ab), axis=-1), axis=1)
