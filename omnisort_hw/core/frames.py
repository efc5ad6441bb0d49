"""Frames, rotations and the laser plane as geometry.md fixes them (degrees at the boundary).

R_SC maps camera-frame vectors into the system frame S:
R_SC = Rz(yaw) Ry(pitch) Rx(roll) R_nom, with R_nom: x_C = X_S, y_C = -Y_S, z_C = -Z_S.
The laser plane has normal n = Ry(pitch_l) Rx(roll_l) (0, 0, 1) and passes through (0, 0, -d).
"""

from __future__ import annotations

import numpy as np

R_NOM = np.diag([1.0, -1.0, -1.0])


def rot_x(rad: float) -> np.ndarray:
    c, s = np.cos(rad), np.sin(rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(rad: float) -> np.ndarray:
    c, s = np.cos(rad), np.sin(rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(rad: float) -> np.ndarray:
    c, s = np.cos(rad), np.sin(rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def camera_rotation(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R_SC from angles in radians: Rz(yaw) Ry(pitch) Rx(roll) R_nom, written out (it sits in
    the inner loop of the joint solver)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    # Columns 2 and 3 of Rz Ry Rx are negated by R_nom = diag(1, -1, -1).
    return np.array(
        [
            [cy * cp, -(cy * sp * sr - sy * cr), -(cy * sp * cr + sy * sr)],
            [sy * cp, -(sy * sp * sr + cy * cr), -(sy * sp * cr - cy * sr)],
            [-sp, -cp * sr, -cp * cr],
        ]
    )


def camera_angles(R_SC: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians of a camera rotation (inverse of camera_rotation)."""
    M = R_SC @ R_NOM.T
    pitch = float(np.arcsin(np.clip(-M[2, 0], -1.0, 1.0)))
    roll = float(np.arctan2(M[2, 1], M[2, 2]))
    yaw = float(np.arctan2(M[1, 0], M[0, 0]))
    return roll, pitch, yaw


def laser_normal(roll: float, pitch: float) -> np.ndarray:
    """Unit normal of the laser plane in S from its angles in radians."""
    return np.array([np.cos(roll) * np.sin(pitch), -np.sin(roll), np.cos(roll) * np.cos(pitch)])


def laser_angles(normal: np.ndarray) -> tuple[float, float]:
    """(roll, pitch) in radians of a laser plane normal (sign made to point up)."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    if n[2] < 0:
        n = -n
    return float(-np.arcsin(np.clip(n[1], -1.0, 1.0))), float(np.arctan2(n[0], n[2]))


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation matrix closest to M in the Frobenius sense."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def rays_to_plane(rays_S: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Points where rays from the origin meet the plane n . p = offset (NaN where parallel)."""
    denom = rays_S @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.abs(denom) > 1e-12, offset / denom, np.nan)
    return rays_S * t[..., None]


def great_circle_normal(rays: np.ndarray) -> np.ndarray:
    """Unit normal of the plane through the origin that best contains the given unit rays."""
    _, _, vt = np.linalg.svd(np.asarray(rays, float), full_matrices=False)
    return vt[-1]
