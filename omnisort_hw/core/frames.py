"""Frames, rotations, poses and the laser plane: the one home of the project's geometry helpers.

Conventions are those of docs/frames.md: radians inside, degrees at the boundary. Functions
whose arguments or results are named `*_deg` take or give degrees (records, cell files, UR
poses); every other angle is in radians. Lengths are millimetres.

R_SC maps camera-frame vectors into the system frame S:
R_SC = Rz(yaw) Ry(pitch) Rx(roll) R_nom, with R_nom: x_C = X_S, y_C = -Y_S, z_C = -Z_S.
The laser plane has normal n = Ry(pitch_l) Rx(roll_l) (0, 0, 1) and passes through (0, 0, -d).
Roll, pitch, yaw of a pose are Z-Y-X: R = Rz(yaw) Ry(pitch) Rx(roll) (UR's RPY as well).
Poses are 4x4 rigid transforms; the batched helpers accept any number of leading axes.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

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


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rz(yaw) Ry(pitch) Rx(roll) from angles in radians (the project's Z-Y-X order)."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def rpy_angles(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians of R = Rz(yaw) Ry(pitch) Rx(roll), pitch in [-pi/2, pi/2]."""
    pitch = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    roll = float(np.arctan2(R[2, 1], R[2, 2]))
    yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    return roll, pitch, yaw


def rpy_deg(R: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in degrees of R (the boundary form of `rpy_angles`)."""
    roll, pitch, yaw = np.degrees(rpy_angles(R))
    return float(roll), float(pitch), float(yaw)


def homogeneous(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 rigid transform from a rotation and a translation (mm)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


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


# ---- poses (mm; degrees where the name says so), batched ----------------------------------


def as_batch(arr: np.ndarray, tail: tuple[int, ...], what: str) -> tuple[np.ndarray, tuple]:
    """Flatten the leading axes of `arr` whose trailing shape must be `tail`."""
    a = np.asarray(arr, dtype=float)
    if a.shape[a.ndim - len(tail) :] != tail:
        raise ValueError(
            f"{what} must have shape (..., {', '.join(map(str, tail))}), got {a.shape}"
        )
    batch = a.shape[: a.ndim - len(tail)]
    return a.reshape((-1, *tail)), batch


def compose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Homogeneous transforms from rotations (N, 3, 3) and translations (N, 3)."""
    T = np.zeros((R.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = t
    T[:, 3, 3] = 1.0
    return T


def pose_from_xyz_rpy(xyz_mm: np.ndarray, rpy_deg: np.ndarray) -> np.ndarray:
    """Pose (..., 4, 4) from a position (mm) and roll, pitch, yaw (deg): R = Rz·Ry·Rx (UR's RPY)."""
    t, batch = as_batch(xyz_mm, (3,), "xyz_mm")
    e, batch_e = as_batch(rpy_deg, (3,), "rpy_deg")
    t, e = np.broadcast_arrays(t, e)
    R = Rotation.from_euler("xyz", e, degrees=True).as_matrix()
    out_batch = np.broadcast_shapes(batch, batch_e)
    return compose(R, t).reshape(*out_batch, 4, 4)


def xyz_rpy_from_pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (..., 3) mm and roll, pitch, yaw (..., 3) deg of poses (..., 4, 4)."""
    Tf, batch = as_batch(T, (4, 4), "T")
    rpy = Rotation.from_matrix(Tf[:, :3, :3]).as_euler("xyz", degrees=True)
    return Tf[:, :3, 3].reshape(*batch, 3), rpy.reshape(*batch, 3)


def pose_from_xyz_rotvec(xyz_mm: np.ndarray, rotvec_deg: np.ndarray) -> np.ndarray:
    """Pose (..., 4, 4) from a position (mm) and a rotation vector (axis times angle in deg)."""
    t, batch = as_batch(xyz_mm, (3,), "xyz_mm")
    r, batch_r = as_batch(rotvec_deg, (3,), "rotvec_deg")
    t, r = np.broadcast_arrays(t, r)
    R = Rotation.from_rotvec(r, degrees=True).as_matrix()
    return compose(R, t).reshape(*np.broadcast_shapes(batch, batch_r), 4, 4)


def xyz_rotvec_from_pose(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position (..., 3) mm and rotation vector (..., 3) deg of poses (..., 4, 4)."""
    Tf, batch = as_batch(T, (4, 4), "T")
    rv = Rotation.from_matrix(Tf[:, :3, :3]).as_rotvec(degrees=True)
    return Tf[:, :3, 3].reshape(*batch, 3), rv.reshape(*batch, 3)


def translation_pose(xyz_mm: np.ndarray) -> np.ndarray:
    """Pure translation poses (..., 4, 4) from positions (..., 3) mm."""
    t, batch = as_batch(xyz_mm, (3,), "xyz_mm")
    return compose(np.broadcast_to(np.eye(3), (t.shape[0], 3, 3)), t).reshape(*batch, 4, 4)


def invert_pose(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4), using the transpose of the rotation."""
    Tf, batch = as_batch(T, (4, 4), "T")
    Rt = np.swapaxes(Tf[:, :3, :3], 1, 2)
    return compose(Rt, -np.einsum("nij,nj->ni", Rt, Tf[:, :3, 3])).reshape(*batch, 4, 4)


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Angle (deg) of the rotation between R_a and R_b (..., 3, 3), accurate near zero."""
    d = np.swapaxes(R_a, -1, -2) @ R_b
    skew = np.stack(
        [d[..., 2, 1] - d[..., 1, 2], d[..., 0, 2] - d[..., 2, 0], d[..., 1, 0] - d[..., 0, 1]],
        axis=-1,
    )
    trace = d[..., 0, 0] + d[..., 1, 1] + d[..., 2, 2]
    return np.degrees(np.arctan2(0.5 * np.linalg.norm(skew, axis=-1), 0.5 * (trace - 1.0)))


def tangent_basis(rays: np.ndarray) -> np.ndarray:
    """Two unit vectors perpendicular to each ray, (N, 2, 3)."""
    helper = np.where(np.abs(rays[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(rays, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(rays, t1)
    return np.stack([t1, t2], axis=1)
