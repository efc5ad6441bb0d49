"""Checkerboard corner detection on fisheye images.

Detection tries OpenCV's classic detector on a ladder of scales chosen from the image size
and the board: from the coarsest scale at which the smallest plausible squares (a board
seen small near the rim) stay large enough for the detector, up to full resolution, and
upsampled for small images; OpenCV's sector-based detector is the fallback. Every candidate
grid must pass consistency checks (no folded, flipped or shifted grid, no partial board
taken for a full one) before it is accepted. Corners are refined to sub-pixel on the
full-resolution image with a window sized from the local square size, and each corner is
then checked to sit at an intensity saddle; corners that fail are reported, not hidden.
Order: row by row, `cols` corners a row, starting from the end whose first corner is
higher in the image (a fixed choice of the two orderings OpenCV may return, so results
compare across images and with ground truth).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from omnisort_hw.core.choices import SQUARE_RANGE_MM
from omnisort_hw.errors import FeatureNotFoundError

_CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
_SB_FLAGS = cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
# The classic detector needs squares of roughly this many pixels (its quads come from
# dilated binary blobs); larger squares only cost time.
_MIN_SQUARE_PX = 12.0
# Smallest board a person would present: its squares span this fraction of what a board
# filling the image's short side would have (a small board near the rim of the circle).
_SMALLEST_BOARD = 0.25
_LADDER = (0.25, 0.35, 0.5, 0.7, 1.0, 1.5, 2.0, 2.5, 3.0)
# The classic detector's quad linking succeeds or fails erratically with the scale, so a
# calibration, where every board counts, searches a denser ladder (steps of ~1.2).
_DENSE_LADDER = (0.25, 0.3, 0.35, 0.42, 0.5, 0.6, 0.7, 0.85, 1.0, 1.2, 1.45, 1.75, 2.1, 2.5, 3.0)
_MAX_UPSAMPLED_PX = 2000  # short side of an upsampled copy, at most
# Ring that samples the intensity around a corner, as a fraction of the local spacing.
_RING = 0.35
_RING_SAMPLES = 32


# Inner corners per side: far beyond any printable calibration board, and a bound on the
# detector's work for a mistyped size.
MAX_CORNERS = 60


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
        lo, hi = SQUARE_RANGE_MM
        if not (2 <= cols <= MAX_CORNERS and 2 <= rows <= MAX_CORNERS) or not lo <= square_mm <= hi:
            raise ValueError(
                f"board {text!r} with square {square_mm:g} mm is not a board (2 to {MAX_CORNERS} "
                f"inner corners each way, a square of {lo:g} to {hi:g} mm)"
            )
        return cls(cols, rows, float(square_mm))

    @property
    def size(self) -> tuple[int, int]:
        return (self.cols, self.rows)

    def object_points(self) -> np.ndarray:
        """(cols*rows, 3) corner coordinates on the board plane (Z = 0), mm, row by row."""
        xs, ys = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
        return pts * self.square_mm


@dataclass
class BoardDetection:
    """A full board's corners (cols*rows, 2) and, per corner, why it is not trusted."""

    corners: np.ndarray
    rejected: dict[int, str] = field(default_factory=dict)
    scale: float = 1.0

    @property
    def good(self) -> np.ndarray:
        """Boolean mask of the corners that passed every check."""
        mask = np.ones(len(self.corners), bool)
        mask[list(self.rejected)] = False
        return mask


def to_gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image


def detection_scales(
    image_size: tuple[int, int], board: tuple[int, int], dense: bool = False
) -> list[float]:
    """Scales to search at, in order: from the coarsest that keeps the smallest plausible
    squares at least _MIN_SQUARE_PX wide, finer up to full resolution, then upsampled (cubic)
    while the short side stays within _MAX_UPSAMPLED_PX, then the coarser ones (a board close
    to the lens)."""
    short = min(image_size)
    smallest_square = _SMALLEST_BOARD * short / (max(board) + 1)
    s_min = _MIN_SQUARE_PX / smallest_square
    ladder = _DENSE_LADDER if dense else _LADDER
    fine = [
        s for s in ladder if s >= s_min * 0.999 and (s <= 1.0 or s * short <= _MAX_UPSAMPLED_PX)
    ]
    if not fine or fine[0] > 1.0:
        fine = [s for s in ladder if s >= 1.0 and s * short <= _MAX_UPSAMPLED_PX] or [1.0]
    coarse = [s for s in reversed(ladder) if s < fine[0] and s * short >= 160]
    return fine + coarse


def _canonical_order(corners: np.ndarray, cols: int, rows: int) -> np.ndarray:
    """Pick, of the row-major orderings OpenCV can return (forward or reversed), the one whose
    first corner is higher in the image (then further left)."""
    grid = corners.reshape(rows, cols, 2)
    reverse = grid[::-1, ::-1].reshape(-1, 2)
    first, alt = corners[0], reverse[0]
    if (alt[1], alt[0]) < (first[1], first[0]):
        return reverse
    return corners


def _spacing(corners: np.ndarray, cols: int, rows: int) -> np.ndarray:
    """Per corner, the distance to its nearest grid neighbour (pixels)."""
    grid = corners.reshape(rows, cols, 2)
    dx = np.linalg.norm(np.diff(grid, axis=1), axis=2)
    dy = np.linalg.norm(np.diff(grid, axis=0), axis=2)
    near = np.full((rows, cols), np.inf)
    near[:, :-1] = np.minimum(near[:, :-1], dx)
    near[:, 1:] = np.minimum(near[:, 1:], dx)
    near[:-1, :] = np.minimum(near[:-1, :], dy)
    near[1:, :] = np.minimum(near[1:, :], dy)
    return near.ravel()


def _refine_window(corners: np.ndarray, cols: int, rows: int) -> int:
    """Half-size of the sub-pixel window: a quarter of the smallest local corner spacing."""
    return int(np.clip(0.25 * _spacing(corners, cols, rows).min(), 2, 12))


def grid_problem(corners: np.ndarray, cols: int, rows: int) -> str | None:
    """Why a candidate grid is not a plausible view of a flat board, or None.

    Every cell must be a convex quadrilateral turning the same way as all the others (no
    fold or flip), and neighbouring edges along a row or column may change length only
    smoothly (a lens does not halve a square from one to the next; a skipped or repeated
    corner does)."""
    g = corners.reshape(rows, cols, 2)
    quad = [g[:-1, :-1], g[:-1, 1:], g[1:, 1:], g[1:, :-1]]
    turns = []
    for k in range(4):
        a, b, c = quad[k], quad[(k + 1) % 4], quad[(k + 2) % 4]
        e1, e2 = b - a, c - b
        turns.append(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0])
    turns_arr = np.stack(turns)
    if not (np.all(turns_arr > 0) or np.all(turns_arr < 0)):
        return "grid folds or its cells are not convex"
    for axis in (0, 1):
        edges = np.linalg.norm(np.diff(g, axis=axis), axis=2)
        if edges.min() < 1.0:
            return "grid has coincident corners"
        ratio = np.diff(np.log(edges), axis=axis) if edges.shape[axis] > 1 else np.zeros(1)
        if ratio.size and np.abs(ratio).max() > np.log(2.0):
            return "grid spacing jumps between neighbours (skipped or repeated corner)"
    return None


def ring_profiles(gray: np.ndarray, points: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(N, _RING_SAMPLES) intensities on a circle of `radius` pixels around each point."""
    angles = np.linspace(0.0, 2 * np.pi, _RING_SAMPLES, endpoint=False)
    xs = points[:, 0:1] + radius[:, None] * np.cos(angles)[None, :]
    ys = points[:, 1:2] + radius[:, None] * np.sin(angles)[None, :]
    sampled = cv2.remap(
        gray.astype(np.float32),
        xs.astype(np.float32),
        ys.astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    return sampled.astype(np.float64)


def saddle_scores(profiles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per ring: number of dark/bright alternations, relative contrast, and point symmetry.

    A checkerboard corner's ring crosses two dark and two bright sectors (4 sign changes
    about its middle level) and looks the same turned by 180 degrees (symmetry near 1); the
    middle of a square or of an edge does not."""
    lo, hi = profiles.min(axis=1), profiles.max(axis=1)
    mid = 0.5 * (lo + hi)
    sign = profiles > mid[:, None]
    changes = np.sum(sign != np.roll(sign, 1, axis=1), axis=1)
    centred = profiles - profiles.mean(axis=1, keepdims=True)
    turned = np.roll(centred, _RING_SAMPLES // 2, axis=1)
    denom = np.sqrt(np.sum(centred**2, axis=1) * np.sum(turned**2, axis=1)) + 1e-9
    symmetry = np.sum(centred * turned, axis=1) / denom
    # Michelson contrast: a gain (vignetting, uneven light) does not change it.
    return changes, (hi - lo) / (hi + lo + 1.0), symmetry


def _is_saddle(changes: np.ndarray, symmetry: np.ndarray) -> np.ndarray:
    return (changes == 4) & (symmetry > 0.5)


def saddle_mask(
    gray: np.ndarray, points: np.ndarray, radius: np.ndarray, contrast_ref: float
) -> np.ndarray:
    """True where a point sits at a checkerboard saddle: two dark and two bright sectors,
    point-symmetric, with at least a quarter of `contrast_ref` (the board's typical contrast,
    so that noise in a flat square cannot pass)."""
    changes, contrast, symmetry = saddle_scores(ring_profiles(gray, points, radius))
    return _is_saddle(changes, symmetry) & (contrast >= 0.25 * contrast_ref)


def _cell_values(gray: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """Mean intensity inside each cell of a (r, c, 2) grid of corners: its centre and four
    points halfway to its corners, (r-1, c-1)."""
    a, b, c, d = grid[:-1, :-1], grid[:-1, 1:], grid[1:, 1:], grid[1:, :-1]
    centre = 0.25 * (a + b + c + d)
    pts = np.stack([centre, *(0.5 * (centre + q) for q in (a, b, c, d))], axis=-2)
    flat = pts.reshape(-1, 2).astype(np.float32)
    vals = cv2.remap(
        gray.astype(np.float32),
        flat[:, 0:1],
        flat[:, 1:2],
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    # In log intensity, so that a gain (vignetting, uneven light) cancels in differences.
    return np.log1p(vals.reshape(pts.shape[:-1]).mean(axis=-1))


def _alternation(values: np.ndarray, contrast: float) -> float:
    """Fraction of neighbouring cells (along both grid directions) that differ by at least
    a third of `contrast` with the sign the checkerboard's parity demands."""
    r, c = np.indices(values.shape)
    sign = np.where((r + c) % 2 == 0, 1.0, -1.0)
    ok, total = 0, 0
    for axis in (0, 1):
        if values.shape[axis] < 2:
            continue
        diff = np.diff(values, axis=axis) * -np.take(sign, range(values.shape[axis] - 1), axis)
        ref = np.median(np.abs(diff)) if contrast <= 0 else contrast
        ok += int(np.sum(diff * np.sign(np.median(diff)) > ref / 3))
        total += diff.size
    return ok / max(total, 1)


def _checker_problem(gray: np.ndarray, corners: np.ndarray, cols: int, rows: int) -> str | None:
    """Why the cells between the corners are not a checkerboard, or None.

    Inside the grid each cell must be dark where its neighbours are bright and the other way
    round (a skipped or repeated corner puts a cell across two squares). Past the board's
    outer squares, a strip of cells must NOT alternate: the board ends there (a margin or the
    background), else the grid found is part of a larger board or shifted by a square."""
    g = corners.reshape(rows, cols, 2)
    inner = _cell_values(gray, g)
    contrast = float(np.median(np.abs(np.diff(inner, axis=1)))) if cols > 2 else 0.0
    if _alternation(inner, 0.0) < 0.9:
        return "the cells between the corners do not alternate dark and bright"
    h, w = gray.shape[:2]
    gray32 = cv2.GaussianBlur(gray, (0, 0), 1.0).astype(np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 20, 1e-2)
    for grid in (g, g[::-1], g.transpose(1, 0, 2), g.transpose(1, 0, 2)[::-1]):
        edge = 3 * grid[0] - 3 * grid[1] + grid[2] if len(grid) > 2 else 2 * grid[0] - grid[1]
        step = np.linalg.norm(edge - grid[0], axis=1)
        half = int(np.clip(0.25 * np.median(step), 2, 30))
        if not np.all((edge > half) & (edge < np.array([w, h]) - 1 - half)):
            continue
        edge = cv2.cornerSubPix(
            gray, edge.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), criteria
        ).reshape(-1, 2)
        # Middle of each cell of the next row out, a third of a square past the board's edge.
        mid = 0.5 * (edge[:-1] + edge[1:])
        past = (mid + 0.35 * (mid - 0.5 * (grid[0][:-1] + grid[0][1:]))).astype(np.float32)
        vals = cv2.remap(gray32, past[:, 0:1], past[:, 1:2], cv2.INTER_LINEAR).ravel()
        d = np.diff(np.log1p(vals.astype(np.float64)))
        # Steps between neighbours that are strong and flip sign like a checkerboard's; the
        # last cells may run off the board into the rim, so three quarters suffice.
        ok = np.abs(d) > contrast / 3
        ok[1:] &= d[1:] * d[:-1] < 0
        if len(d) >= 2 and np.mean(ok) >= 0.75:
            return "the grid continues past its edge (a larger board, or one shifted)"
    return None


Detector = Literal["any", "quick", "sb"]


def _candidates(
    gray: np.ndarray, cols: int, rows: int, dense: bool = False, detector: Detector = "any"
) -> Iterator[tuple[np.ndarray, float]]:
    """Candidate grids (full-resolution pixel coordinates, scale) in the order to try: the
    classic detector over the scale ladder, then the sector-based one at the two finest
    scales ("any"); only the classic one behind OpenCV's fast check ("quick": a search
    over many views, most of them without a board); only the sector-based one ("sb")."""
    scales = detection_scales((gray.shape[1], gray.shape[0]), (cols, rows), dense)
    resized: dict[float, np.ndarray] = {}

    def at(s: float) -> np.ndarray:  # each scale resized once, for both detectors
        if s not in resized:
            interp = cv2.INTER_AREA if s < 1 else cv2.INTER_CUBIC
            resized[s] = (
                gray if s == 1.0 else cv2.resize(gray, None, fx=s, fy=s, interpolation=interp)
            )
        return resized[s]

    if detector != "sb":
        flags = _CLASSIC_FLAGS | (cv2.CALIB_CB_FAST_CHECK if detector == "quick" else 0)
        for s in scales:
            ok, pts = cv2.findChessboardCorners(at(s), (cols, rows), flags=flags)
            if ok:
                yield (pts.reshape(-1, 2).astype(np.float64) + 0.5) / s - 0.5, s
    if detector == "quick":
        return
    for s in scales[:2]:
        ok, pts = cv2.findChessboardCornersSB(at(s), (cols, rows), flags=_SB_FLAGS)
        if ok:
            yield (pts.reshape(-1, 2).astype(np.float64) + 0.5) / s - 0.5, s


def detect_board(
    image: np.ndarray,
    board: tuple[int, int] | BoardSpec,
    dense: bool = False,
    detector: Detector = "any",
) -> BoardDetection:
    """The full board's corners with per-corner checks, or FeatureNotFoundError (the reason
    names the last check that failed). `dense` searches the denser scale ladder (calibration);
    `detector` picks the detectors tried (see `_candidates`)."""
    cols, rows = board.size if isinstance(board, BoardSpec) else board
    gray = to_gray(image)
    reason = "the detector found no grid at any scale"
    for found, scale in _candidates(gray, cols, rows, dense, detector):
        problem = grid_problem(found, cols, rows) or _checker_problem(gray, found, cols, rows)
        if problem is not None:
            reason = problem
            continue
        return _refined(gray, found, cols, rows, scale)
    raise FeatureNotFoundError(
        f"no complete {cols}x{rows} checkerboard found ({reason}; all {cols * rows} inner "
        "corners must be visible; check the board size and that the board is fully in view)"
    )


def _refined(
    gray: np.ndarray, found: np.ndarray, cols: int, rows: int, scale: float
) -> BoardDetection:
    """Sub-pixel refinement, then the saddle check of every refined corner."""
    half = _refine_window(found, cols, rows)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
    refined = cv2.cornerSubPix(
        gray, found.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), criteria
    )
    corners = _canonical_order(refined.reshape(-1, 2).astype(np.float64), cols, rows)
    start = _canonical_order(found, cols, rows)
    spacing = _spacing(corners, cols, rows)
    changes, contrast, symmetry = saddle_scores(ring_profiles(gray, corners, _RING * spacing))
    rejected: dict[int, str] = {}
    moved = np.linalg.norm(corners - start, axis=1)
    low = contrast < 0.25 * np.median(contrast)
    for k in np.flatnonzero(~_is_saddle(changes, symmetry) | low | (moved > half)):
        if moved[k] > half:
            rejected[int(k)] = f"refinement moved it {moved[k]:.1f} px (window {half} px)"
        elif low[k]:
            rejected[int(k)] = (
                f"low contrast ({contrast[k]:.2f} vs median {np.median(contrast):.2f})"
            )
        else:
            rejected[int(k)] = (
                f"not at an intensity saddle ({changes[k]} sign changes, symmetry "
                f"{symmetry[k]:.2f})"
            )
    return BoardDetection(corners, rejected, scale)


def detect_corners(
    image: np.ndarray, board: tuple[int, int] | BoardSpec, detector: Detector = "any"
) -> np.ndarray:
    """Inner corners of the full board, (cols*rows, 2) float pixels, or FeatureNotFoundError."""
    return detect_board(image, board, detector=detector).corners
