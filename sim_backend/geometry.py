"""Frames and small geometry for the simulated cell (geometry.md conventions, millimetres).

Rotations: `rot_x/rot_y/rot_z` take degrees. The camera rotation is
`R_SC = Rz(yaw) Ry(pitch) Rx(roll) R_nom` with `R_nom` mapping C to S (x_C = X_S,
y_C = -Y_S, z_C = -Z_S); the laser plane has normal `Ry(pitch_l) Rx(roll_l) (0, 0, 1)` and
passes through (0, 0, -d). A `Rect` is an oriented planar rectangle (a box face, a wall face,
a board) used for analytic shading, truth features and the exact laser polylines.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from omnisort_hw.core import frames


def rot_x(deg: float) -> np.ndarray:
    """Rotation about X by `deg` degrees (right-handed)."""
    return frames.rot_x(np.deg2rad(deg))


def rot_y(deg: float) -> np.ndarray:
    """Rotation about Y by `deg` degrees (right-handed)."""
    return frames.rot_y(np.deg2rad(deg))


def rot_z(deg: float) -> np.ndarray:
    """Rotation about Z by `deg` degrees (right-handed)."""
    return frames.rot_z(np.deg2rad(deg))


def rpy_matrix(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll), the Z-Y-X order used everywhere in the project."""
    return rot_z(yaw_deg) @ rot_y(pitch_deg) @ rot_x(roll_deg)


def matrix_rpy(R: np.ndarray) -> tuple[float, float, float]:
    """Inverse of `rpy_matrix`: (roll, pitch, yaw) in degrees, pitch in [-90, 90]."""
    pitch = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
    roll = np.arctan2(R[2, 1], R[2, 2])
    yaw = np.arctan2(R[1, 0], R[0, 0])
    return float(np.rad2deg(roll)), float(np.rad2deg(pitch)), float(np.rad2deg(yaw))


def camera_rotation(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """R_SC: maps camera-frame vectors into S (the core's convention, degrees here)."""
    return frames.camera_rotation(*np.deg2rad([roll_deg, pitch_deg, yaw_deg]))


def laser_normal(roll_deg: float, pitch_deg: float) -> np.ndarray:
    """Unit normal of the laser plane in S: Ry(pitch) Rx(roll) (0, 0, 1)."""
    return frames.laser_normal(*np.deg2rad([roll_deg, pitch_deg]))


def homogeneous(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 rigid transform from a rotation and a translation."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def invert_transform(T: np.ndarray) -> np.ndarray:
    """Inverse of a 4x4 rigid transform."""
    R, t = T[:3, :3], T[:3, 3]
    return homogeneous(R.T, -R.T @ t)


def transform_points(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (..., 3) points."""
    return np.asarray(pts, float) @ T[:3, :3].T + T[:3, 3]


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
