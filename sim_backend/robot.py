"""The simulated UR arm: a pybullet multibody whose link frames follow UR's published DH chain
(taken from the core's kinematics, `omnisort_hw.core.kinematics`), with simple geometry
(cylinders along the DH offsets) and a parallel gripper.

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

from omnisort_hw.core.frames import homogeneous, rot_x
from omnisort_hw.core.kinematics import URModel, forward, get_model
from sim_backend.scene import GripperSpec

MM = 1e-3


LINK_RADIUS_MM: dict[str, tuple[float, ...]] = {
    "ur3e": (50.0, 45.0, 38.0, 32.0, 32.0, 30.0),
    "ur5e": (68.0, 60.0, 48.0, 40.0, 40.0, 36.0),
    "ur10e": (85.0, 78.0, 60.0, 48.0, 48.0, 44.0),
}


def ur_model(name: str) -> URModel:
    """The core's UR model (DH table, joint limits) for a scene's `robot.model`."""
    return get_model(name)


def tcp_tool(tcp_offset_mm: float) -> np.ndarray:
    """The flange-to-TCP transform: `tcp_offset_mm` along the flange's z."""
    return homogeneous(np.eye(3), np.array([0.0, 0.0, tcp_offset_mm]))


def tcp_pose(model: URModel, q_deg: np.ndarray, tcp_offset_mm: float) -> np.ndarray:
    """T_B_tcp (4x4, mm) for joints `q_deg`, through the core's forward kinematics."""
    return forward(model, np.asarray(q_deg, float), tcp_tool(tcp_offset_mm))


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
    model: URModel,
    T_S_B: np.ndarray,
    gripper: GripperSpec,
    pedestal_mm: float,
    rgba: list[float],
) -> ArmBodies:
    """Create the arm as one kinematic multibody whose link frames follow the DH chain."""
    r = LINK_RADIUS_MM[model.name]
    d, a = model.d_mm, model.a_mm
    alpha = np.asarray(model.alpha, float)
    base = _ShapeList()
    base.cylinder(np.array([0.0, 0.0, -pedestal_mm - 1.0]), np.array([0.0, 0.0, 40.0]), r[0] * 1.2)
    base_col, base_vis = base.build(client, [0.35, 0.36, 0.38, 1.0])
    cols, viss, positions, orns, parents, jtypes, axes = [], [], [], [], [], [], []
    for i in range(6):
        shapes = _ShapeList()
        ri = r[i]
        shapes.cylinder(np.array([0.0, 0.0, -1.2 * ri]), np.array([0.0, 0.0, 1.2 * ri]), ri)
        top = np.array([0.0, 0.0, d[i]])
        if abs(d[i]) > 1.0:
            shapes.cylinder(np.zeros(3), top, 0.85 * ri)
        if abs(a[i]) > 1.0:
            shapes.cylinder(top, top + np.array([a[i], 0.0, 0.0]), 0.85 * ri)
        col, vis = shapes.build(client, rgba)
        cols.append(col)
        viss.append(vis)
        if i == 0:
            positions.append([0.0, 0.0, 0.0])
            orns.append([0.0, 0.0, 0.0, 1.0])
        else:
            positions.append([a[i - 1] * MM, 0.0, d[i - 1] * MM])
            orns.append(list(Rotation.from_matrix(rot_x(alpha[i - 1])).as_quat()))
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
    positions.append([a[5] * MM, 0.0, d[5] * MM])
    orns.append(list(Rotation.from_matrix(rot_x(alpha[5])).as_quat()))
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
