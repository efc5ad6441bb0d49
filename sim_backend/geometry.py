"""Planar rectangles and box faces of the simulated cell (millimetres, docs/frames.md).

A `Rect` is an oriented planar rectangle (a box face, a wall face, a board) used for analytic
shading, truth features and the exact laser polylines. Rotations, poses and the laser plane
come from the core's `omnisort_hw.core.frames` (radians inside; the scene's degrees are
converted where they are read).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Rect:
    """A planar rectangle: `origin` + a `axis_u` + b `axis_v`, a in [0, size_u], b in [0, size_v].

    `axis_u`, `axis_v` are orthonormal; `normal` = the side the rectangle is seen from (its
    front). Coordinates (a, b) are the rectangle's own 2D frame, used by pattern shaders.
    """

    name: str
    origin: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    size_u: float
    size_v: float
    normal: np.ndarray

    @property
    def plane_offset(self) -> float:
        """c in the plane equation normal . X = c."""
        return float(self.normal @ self.origin)

    def point(self, a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
        """3D point(s) of rectangle coordinates (a, b)."""
        a_arr = np.asarray(a, float)[..., None]
        b_arr = np.asarray(b, float)[..., None]
        return self.origin + a_arr * self.axis_u + b_arr * self.axis_v

    def corners(self) -> np.ndarray:
        """The four corners (4, 3) in order (0,0), (u,0), (u,v), (0,v)."""
        return self.point(
            np.array([0.0, self.size_u, self.size_u, 0.0]),
            np.array([0.0, 0.0, self.size_v, self.size_v]),
        )

    def plane_segment(
        self, normal: np.ndarray, offset: float
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The part of the line {n . X = offset} inside the rectangle, as two 3D points, or None.

        Solved in the rectangle's 2D frame: n.(o + a u + b v) = offset is a line in (a, b),
        clipped to the rectangle with Liang-Barsky.
        """
        ka = float(normal @ self.axis_u)
        kb = float(normal @ self.axis_v)
        k0 = float(offset - normal @ self.origin)
        if abs(ka) < 1e-12 and abs(kb) < 1e-12:
            return None
        # A point on the 2D line and its direction.
        norm2 = ka * ka + kb * kb
        p0 = np.array([ka, kb]) * (k0 / norm2)
        direction = np.array([-kb, ka]) / np.sqrt(norm2)
        lo, hi = -np.inf, np.inf
        for axis, limit in ((0, self.size_u), (1, self.size_v)):
            d = direction[axis]
            if abs(d) < 1e-12:
                if p0[axis] < 0.0 or p0[axis] > limit:
                    return None
                continue
            t0 = (0.0 - p0[axis]) / d
            t1 = (limit - p0[axis]) / d
            lo, hi = max(lo, min(t0, t1)), min(hi, max(t0, t1))
        if hi - lo <= 1e-9:
            return None
        a0, b0 = p0 + lo * direction
        a1, b1 = p0 + hi * direction
        return self.point(a0, b0), self.point(a1, b1)


def box_faces(name: str, center: np.ndarray, R: np.ndarray, half: np.ndarray) -> list[Rect]:
    """The six outward-facing faces of an oriented box as `Rect`s (names `name.+x` etc.)."""
    faces = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            n = R[:, axis] * sign
            u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
            u = R[:, u_axis]
            v = R[:, v_axis] * sign
            origin = center + n * half[axis] - u * half[u_axis] - v * half[v_axis]
            label = f"{name}.{'+' if sign > 0 else '-'}{'xyz'[axis]}"
            faces.append(Rect(label, origin, u, v, 2 * half[u_axis], 2 * half[v_axis], n))
    return faces
