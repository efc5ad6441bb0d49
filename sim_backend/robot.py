"""The simulated UR arm: UR's published DH parameters, forward kinematics, a damped least-squares
inverse kinematics for the simulator's own linear moves, and a pybullet multibody with simple
geometry (cylinders along the DH offsets) plus a parallel gripper.

Frames: B is DH frame 0 (the controller's base frame); the flange is DH frame 6; the TCP is
`tcp_offset_mm` along the flange's z. Millimetres and degrees at the interface, metres inside
pybullet. The arm is kinematic (massless links driven by `resetJointState`); grasped cubes
follow through a fixed constraint while the physics steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from sim_backend.geometry import homogeneous, rot_x, rot_z
from sim_backend.scene import GripperSpec

MM = 1e-3


@dataclass(frozen=True)
class DHTable:
    """Standard DH parameters of a UR model (UR's published table): d and a in mm, alpha in deg."""

    d: tuple[float, ...]
    a: tuple[float, ...]
    alpha_deg: tuple[float, ...]
    link_radius_mm: tuple[float, ...]


_ALPHA = (90.0, 0.0, 0.0, 90.0, -90.0, 0.0)
UR_DH: dict[str, DHTable] = {
    "UR3e": DHTable(
        (151.85, 0.0, 0.0, 131.05, 85.35, 92.1),
        (0.0, -243.55, -213.2, 0.0, 0.0, 0.0),
        _ALPHA,
        (50.0, 45.0, 38.0, 32.0, 32.0, 30.0),
    ),
    "UR5e": DHTable(
        (162.5, 0.0, 0.0, 133.3, 99.7, 99.6),
        (0.0, -425.0, -392.2, 0.0, 0.0, 0.0),
        _ALPHA,
        (68.0, 60.0, 48.0, 40.0, 40.0, 36.0),
    ),
    "UR10e": DHTable(
        (180.7, 0.0, 0.0, 174.15, 119.85, 116.55),
        (0.0, -612.7, -571.55, 0.0, 0.0, 0.0),
        _ALPHA,
        (85.0, 78.0, 60.0, 48.0, 48.0, 44.0),
    ),
}


def dh_step(d: float, a: float, alpha_deg: float, theta_deg: float) -> np.ndarray:
    """Rz(theta) Tz(d) Tx(a) Rx(alpha) as a 4x4 (mm)."""
    T = homogeneous(rot_z(theta_deg), np.zeros(3))
    F = homogeneous(rot_x(alpha_deg), np.array([a, 0.0, d]))
    return T @ F


def forward_frames(dh: DHTable, q_deg: np.ndarray) -> list[np.ndarray]:
    """Frames 0..6 in B (4x4, mm) for joints `q_deg`."""
    frames = [np.eye(4)]
    for i in range(6):
        frames.append(frames[-1] @ dh_step(dh.d[i], dh.a[i], dh.alpha_deg[i], float(q_deg[i])))
    return frames


def forward(dh: DHTable, q_deg: np.ndarray, tcp_offset_mm: float = 0.0) -> np.ndarray:
    """T_B_tcp (4x4, mm): the flange pose moved `tcp_offset_mm` along its z."""
    T = forward_frames(dh, q_deg)[-1]
    out = T.copy()
    out[:3, 3] = T[:3, 3] + T[:3, 2] * tcp_offset_mm
    return out


def _pose_error(T: np.ndarray, target: np.ndarray) -> np.ndarray:
    """6-vector (position mm, rotation vector rad) taking T to target, in B."""
    dp = target[:3, 3] - T[:3, 3]
    dr = Rotation.from_matrix(target[:3, :3] @ T[:3, :3].T).as_rotvec()
    return np.concatenate([dp, dr])


def inverse_numeric(
    dh: DHTable,
    target: np.ndarray,
    q_seed_deg: np.ndarray,
    tcp_offset_mm: float = 0.0,
    tol_mm: float = 1e-3,
    tol_rad: float = 1e-6,
    max_iter: int = 200,
) -> np.ndarray | None:
    """Joints (deg) near `q_seed_deg` reaching `target` (T_B_tcp, mm), or None.

    Damped least squares on a numerical Jacobian; used for the small steps of a linear move,
    where the seed is the previous waypoint so the solution stays on the same branch.
    """
    q = np.deg2rad(np.asarray(q_seed_deg, float)).copy()
    scale = np.array([1.0, 1.0, 1.0, 500.0, 500.0, 500.0])
    for _ in range(max_iter):
        err = _pose_error(forward(dh, np.rad2deg(q), tcp_offset_mm), target)
        if np.all(np.abs(err[:3]) < tol_mm) and np.all(np.abs(err[3:]) < tol_rad):
            return np.rad2deg(q)
        J = np.empty((6, 6))
        h = 1e-6
        for k in range(6):
            dq = q.copy()
            dq[k] += h
            J[:, k] = -_pose_error(forward(dh, np.rad2deg(dq), tcp_offset_mm), target) / h
        J_s = J * scale[:, None]
        e_s = err * scale
        lam = 1e-2
        step = np.linalg.solve(J_s.T @ J_s + lam * np.eye(6), -J_s.T @ e_s)
        q += np.clip(step, -0.2, 0.2)
    return None


def _cyl_frame(start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, list[float], float]:
    """Centre, quaternion and length of a cylinder (pybullet: along local z) from start to end."""
    axis = end - start
    length = float(np.linalg.norm(axis))
    z = axis / length
    ref = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(ref, z)
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z], axis=1)
    return (start + end) / 2.0, list(Rotation.from_matrix(R).as_quat()), length


class _ShapeList:
    """Accumulates primitives of one link for createVisualShapeArray/createCollisionShapeArray."""

    def __init__(self) -> None:
        self.types: list[int] = []
        self.radii: list[float] = []
        self.half: list[list[float]] = []
        self.lengths: list[float] = []
        self.pos: list[list[float]] = []
        self.orn: list[list[float]] = []

    def cylinder(self, start_mm: np.ndarray, end_mm: np.ndarray, radius_mm: float) -> None:
        centre, quat, length = _cyl_frame(np.asarray(start_mm) * MM, np.asarray(end_mm) * MM)
        self.types.append(p.GEOM_CYLINDER)
        self.radii.append(radius_mm * MM)
        self.half.append([0.0, 0.0, 0.0])
        self.lengths.append(length)
        self.pos.append(list(centre))
        self.orn.append(quat)

    def box(self, centre_mm: np.ndarray, half_mm: np.ndarray) -> None:
        self.types.append(p.GEOM_BOX)
        self.radii.append(0.0)
        self.half.append([float(h) * MM for h in half_mm])
        self.lengths.append(0.0)
        self.pos.append([float(c) * MM for c in centre_mm])
        self.orn.append([0.0, 0.0, 0.0, 1.0])

    def build(self, client: int, rgba: list[float]) -> tuple[int, int]:
        n = len(self.types)
        vis = p.createVisualShapeArray(
            shapeTypes=self.types,
            radii=self.radii,
            halfExtents=self.half,
            lengths=self.lengths,
            rgbaColors=[rgba] * n,
            visualFramePositions=self.pos,
            visualFrameOrientations=self.orn,
            physicsClientId=client,
        )
        col = p.createCollisionShapeArray(
            shapeTypes=self.types,
            radii=self.radii,
            halfExtents=self.half,
            lengths=self.lengths,
            collisionFramePositions=self.pos,
            collisionFrameOrientations=self.orn,
            physicsClientId=client,
        )
        return col, vis


@dataclass
class ArmBodies:
    """Handles of the arm in pybullet: body id, joint indices, gripper link and finger joints."""

    body: int
    joints: tuple[int, ...]
    gripper_link: int
    fingers: tuple[int, int]
    T_S_B: np.ndarray


def build_arm(
    client: int,
    dh: DHTable,
    T_S_B: np.ndarray,
    gripper: GripperSpec,
    pedestal_mm: float,
    rgba: list[float],
) -> ArmBodies:
    """Create the arm as one kinematic multibody whose link frames follow the DH chain."""
    r = dh.link_radius_mm
    base = _ShapeList()
    base.cylinder(np.array([0.0, 0.0, -pedestal_mm - 1.0]), np.array([0.0, 0.0, 40.0]), r[0] * 1.2)
    base_col, base_vis = base.build(client, [0.35, 0.36, 0.38, 1.0])
    cols, viss, positions, orns, parents, jtypes, axes = [], [], [], [], [], [], []
    for i in range(6):
        shapes = _ShapeList()
        ri = r[i]
        shapes.cylinder(np.array([0.0, 0.0, -1.2 * ri]), np.array([0.0, 0.0, 1.2 * ri]), ri)
        top = np.array([0.0, 0.0, dh.d[i]])
        if abs(dh.d[i]) > 1.0:
            shapes.cylinder(np.zeros(3), top, 0.85 * ri)
        if abs(dh.a[i]) > 1.0:
            shapes.cylinder(top, top + np.array([dh.a[i], 0.0, 0.0]), 0.85 * ri)
        col, vis = shapes.build(client, rgba)
        cols.append(col)
        viss.append(vis)
        if i == 0:
            positions.append([0.0, 0.0, 0.0])
            orns.append([0.0, 0.0, 0.0, 1.0])
        else:
            positions.append([dh.a[i - 1] * MM, 0.0, dh.d[i - 1] * MM])
            orns.append(list(Rotation.from_matrix(rot_x(dh.alpha_deg[i - 1])).as_quat()))
        parents.append(i)
        jtypes.append(p.JOINT_REVOLUTE)
        axes.append([0.0, 0.0, 1.0])
    # Gripper body, fixed on the flange (frame 6 = link 6 frame moved by d6 along z).
    body = _ShapeList()
    width = gripper.stroke_mm + 40.0
    body.cylinder(np.zeros(3), np.array([0.0, 0.0, 30.0]), r[5])
    body.box(
        np.array([0.0, 0.0, gripper.body_length_mm / 2.0 + 15.0]),
        np.array([30.0, width / 2.0, gripper.body_length_mm / 2.0 - 15.0]),
    )
    col, vis = body.build(client, [0.20, 0.20, 0.22, 1.0])
    cols.append(col)
    viss.append(vis)
    positions.append([dh.a[5] * MM, 0.0, dh.d[5] * MM])
    orns.append(list(Rotation.from_matrix(rot_x(dh.alpha_deg[5])).as_quat()))
    parents.append(6)
    jtypes.append(p.JOINT_FIXED)
    axes.append([0.0, 0.0, 1.0])
    gripper_index = 6
    for sign in (1.0, -1.0):
        finger = _ShapeList()
        finger.box(
            np.array([0.0, sign * 8.0, gripper.finger_length_mm / 2.0]),
            np.array([22.0, 8.0, gripper.finger_length_mm / 2.0]),
        )
        col, vis = finger.build(client, [0.15, 0.15, 0.16, 1.0])
        cols.append(col)
        viss.append(vis)
        positions.append([0.0, 0.0, gripper.body_length_mm * MM])
        orns.append([0.0, 0.0, 0.0, 1.0])
        parents.append(gripper_index + 1)
        jtypes.append(p.JOINT_PRISMATIC)
        axes.append([0.0, sign, 0.0])
    n = len(cols)
    quat = Rotation.from_matrix(T_S_B[:3, :3]).as_quat()
    arm = p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=base_col,
        baseVisualShapeIndex=base_vis,
        basePosition=list(T_S_B[:3, 3] * MM),
        baseOrientation=list(quat),
        linkMasses=[0.0] * n,
        linkCollisionShapeIndices=cols,
        linkVisualShapeIndices=viss,
        linkPositions=positions,
        linkOrientations=orns,
        linkInertialFramePositions=[[0.0, 0.0, 0.0]] * n,
        linkInertialFrameOrientations=[[0.0, 0.0, 0.0, 1.0]] * n,
        linkParentIndices=parents,
        linkJointTypes=jtypes,
        linkJointAxis=axes,
        physicsClientId=client,
    )
    return ArmBodies(arm, tuple(range(6)), gripper_index, (7, 8), T_S_B)
