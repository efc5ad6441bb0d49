"""Checkerboard corner detection on fisheye images.

Detection runs on reduced copies of the image (fast, and the board's squares look less
distorted there), trying finer scales and OpenCV's sector-based detector only when the
coarse pass fails; the corners are then refined to sub-pixel on the full-resolution image
with a window sized from the local square size. Order: row by row, `cols` corners a row,
starting from the end whose first corner is higher in the image (a fixed choice of the two
orderings OpenCV may return, so results compare across images and with ground truth).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.errors import FeatureNotFoundError

_CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
_SB_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
_SCALES = (0.25, 0.35, 0.5)


@dataclass(frozen=True)
class BoardSpec:
    """A planar checkerboard: inner corners (cols x rows) and square size in mm."""

    cols: int
    rows: int
    square_mm: float

    @classmethod
    def parse(cls, text: str, square_mm: float) -> BoardSpec:
        """'9x6' -> BoardSpec(9, 6, square)."""
        try:
            cols, rows = (int(x) for x in text.lower().split("x"))
        except ValueError as exc:
            raise ValueError(f"board must look like 9x6 (inner corners), got {text!r}") from exc
        if cols < 2 or rows < 2 or square_mm <= 0:
            raise ValueError(f"board {text!r} with square {square_mm} mm is not a board")
        return cls(cols, rows, float(square_mm))

    @property
    def size(self) -> tuple[int, int]:
        return (self.cols, self.rows)

    def object_points(self) -> np.ndarray:
        """(cols*rows, 3) corner coordinates on the board plane (Z = 0), mm, row by row."""
        xs, ys = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
        return pts * self.square_mm


def to_gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


def _canonical_order(corners: np.ndarray, cols: int, rows: int) -> np.ndarray:
    """Pick, of the row-major orderings OpenCV can return (forward or reversed), the one whose
    first corner is higher in the image (then further left)."""
    grid = corners.reshape(rows, cols, 2)
    reverse = grid[::-1, ::-1].reshape(-1, 2)
    first, alt = corners[0], reverse[0]
    if (alt[1], alt[0]) < (first[1], first[0]):
        return reverse
    return corners


def _refine_window(corners: np.ndarray, cols: int, rows: int) -> int:
    """Half-size of the sub-pixel window: a quarter of the smallest local corner spacing."""
    grid = corners.reshape(rows, cols, 2)
    dx = np.linalg.norm(np.diff(grid, axis=1), axis=2).min()
    dy = np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
    return int(np.clip(0.25 * min(dx, dy), 2, 12))


def detect_corners(image: np.ndarray, board: tuple[int, int] | BoardSpec) -> np.ndarray:
    """Inner corners of the full board, (cols*rows, 2) float pixels, or FeatureNotFoundError."""
    cols, rows = board.size if isinstance(board, BoardSpec) else board
    gray = to_gray(image)
    found = None
    for scale in _SCALES:
        small = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        ok, pts = cv2.findChessboardCorners(small, (cols, rows), _CLASSIC_FLAGS)
        if ok:
            found = (pts.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5
            break
    if found is None:
        scale = 0.5
        small = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        ok, pts = cv2.findChessboardCornersSB(small, (cols, rows), _SB_FLAGS)
        if ok:
            found = (pts.reshape(-1, 2).astype(np.float64) + 0.5) / scale - 0.5
    if found is None:
        raise FeatureNotFoundError(
            f"no complete {cols}x{rows} checkerboard found (all {cols * rows} inner corners "
            "must be visible; check the board size and that the board is fully in view)"
        )
    half = _refine_window(found, cols, rows)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
    refined = cv2.cornerSubPix(
        gray, found.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), criteria
    )
    return _canonical_order(refined.reshape(-1, 2).astype(np.float64), cols, rows)
