"""Analytic surface patterns, evaluated at exact points of a planar face.

Patterns are shaded from a point's coordinates (a, b) on its `Rect`, not from textures, so
edges and corners sit exactly where the geometry says (sub-pixel truth by construction) and
supersampling anti-aliases them. Each pattern returns an albedo (n, 3) and a small integer
class per point; the renderer supersamples pixels whose neighbours differ in class.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Array = np.ndarray


@dataclass(frozen=True)
class Marker:
    """A square marker on a wall: centre (a, b) on the wall face and its side length (mm)."""

    name: str
    center_ab: tuple[float, float]
    size: float


@dataclass(frozen=True)
class WallPattern:
    """A target wall's inner face: white below `border` (b, mm above the floor), black above,
    with blue square markers. a runs along the wall, b up from the floor."""

    border: float
    markers: tuple[Marker, ...]
    white: tuple[float, float, float]
    black: tuple[float, float, float]
    marker_color: tuple[float, float, float]

    def shade(self, a: Array, b: Array) -> tuple[Array, Array]:
        """Albedo and class (0 white, 1 black, 2 marker) at face coordinates (a, b)."""
        cls = (b >= self.border).astype(np.int8)
        for m in self.markers:
            half = m.size / 2.0
            inside = (np.abs(a - m.center_ab[0]) <= half) & (np.abs(b - m.center_ab[1]) <= half)
            cls[inside] = 2
        palette = np.array([self.white, self.black, self.marker_color], np.float32)
        return palette[cls], cls


@dataclass(frozen=True)
class CheckerPattern:
    """A checkerboard face: `cols` x `rows` inner corners, squares of `square` mm, a white margin.

    a runs along the columns (right), b down the rows, both from the outer top-left corner;
    the square in the first row and column is black.
    """

    cols: int
    rows: int
    square: float
    margin: float
    white: tuple[float, float, float] = (0.96, 0.96, 0.96)
    black: tuple[float, float, float] = (0.04, 0.04, 0.04)

    @property
    def size(self) -> tuple[float, float]:
        """Outer size (along a, along b) in mm."""
        return (
            (self.cols + 1) * self.square + 2 * self.margin,
            (self.rows + 1) * self.square + 2 * self.margin,
        )

    def inner_corners_ab(self) -> Array:
        """(rows * cols, 2) face coordinates of the inner corners, row by row."""
        i, j = np.meshgrid(np.arange(1, self.cols + 1), np.arange(1, self.rows + 1))
        return np.stack([i.ravel(), j.ravel()], axis=1) * self.square + self.margin

    def shade(self, a: Array, b: Array) -> tuple[Array, Array]:
        """Albedo and class (0 white, 1 black) at face coordinates (a, b)."""
        i = np.floor((a - self.margin) / self.square)
        j = np.floor((b - self.margin) / self.square)
        inside = (i >= 0) & (i <= self.cols) & (j >= 0) & (j <= self.rows)
        cls = (inside & ((i + j) % 2 == 0)).astype(np.int8)
        palette = np.array([self.white, self.black], np.float32)
        return palette[cls], cls


@dataclass(frozen=True)
class FloorPattern:
    """The floor (Z = z): a work-area rectangle [xmin, xmax, ymin, ymax] on a plain floor."""

    z: float
    work_area: tuple[float, float, float, float]
    color: tuple[float, float, float]
    work_area_color: tuple[float, float, float]

    def shade(self, x: Array, y: Array) -> tuple[Array, Array]:
        """Albedo and class (0 floor, 1 work area) at floor points (x, y)."""
        x0, x1, y0, y1 = self.work_area
        cls = ((x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)).astype(np.int8)
        palette = np.array([self.color, self.work_area_color], np.float32)
        return palette[cls], cls
