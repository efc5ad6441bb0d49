"""The cell in 3D, in S (mm), for a picture of it (the page's 3D view): the camera's rotation,
the laser plane, the robot base, the arm's links as it stands (the core's forward kinematics
of its last joint reading), the bins of `[sorting]` and the floor the robot stands on. Read
from system.json, the cell file and the arm's status; nothing is grabbed, moved or written.
A part not calibrated yet is None, with why in `problems`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.frames import rot_z
from omnisort_hw.core.kinematics import get_model, joint_frames
from omnisort_hw.core.pick_planning import BinSpec, SortConfig
from omnisort_hw.errors import OmnisortError
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from omnisort_hw.pipeline.replies import ArmReply, BinReply, GeometryReply, LaserPlaneReply
from omnisort_hw.pipeline.requests import GeometryRequest

LASER_PATCH_MM = 1000.0  # half the side of the laser plane's patch drawn around the emitter


class GeometryRig(Protocol):
    @property
    def store(self) -> CalibrationStore: ...

    @property
    def sort_config(self) -> SortConfig | None: ...

    def arm_joints(self) -> list[float] | None:
        """The arm's last joint reading (deg), None when it has none."""
        ...


def laser_patch(normal: np.ndarray, distance_mm: float, half_mm: float) -> np.ndarray:
    """(4, 3) corners of a square patch of the laser plane centred on the emitter (0, 0, -d)
    (docs/frames.md), in order: its sides along the plane's directions nearest X and Y."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.array([1.0, 0.0, 0.0]) - n[0] * n
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * half_mm
    return np.array([0.0, 0.0, -distance_mm]) + signs[:, :1] * e1 + signs[:, 1:] * e2


def bin_corners_B(spec: BinSpec) -> tuple[np.ndarray, np.ndarray]:
    """(4, 3) corners of a bin's rim and (4, 3) of its foot, in B (mm), in order."""
    sx, sy, sz = spec.size_mm
    local = np.array([[-sx, -sy], [sx, -sy], [sx, sy], [-sx, sy]], float) / 2.0
    xy = local @ rot_z(np.radians(spec.yaw_B_deg))[:2, :2].T + np.asarray(spec.center_B_mm)
    foot = np.column_stack([xy, np.zeros(4)])
    return foot + np.array([0.0, 0.0, sz]), foot


def _to_S(T_SB: np.ndarray, pts_B: np.ndarray) -> list[list[float]]:
    return np.round(pts_B @ T_SB[:3, :3].T + T_SB[:3, 3], 2).tolist()


def arm_points_S(model_name: str, joints_deg: Sequence[float], T_SB: np.ndarray) -> np.ndarray:
    """(8, 3) the base's origin and each DH frame's origin to the flange, in S (mm)."""
    frames = joint_frames(get_model(model_name), np.asarray(joints_deg, float))
    origins_B = np.vstack([np.zeros(3), frames[:, :3, 3]])
    return origins_B @ T_SB[:3, :3].T + T_SB[:3, 3]


@dataclass(frozen=True)
class GeometryResult:
    geometry: GeometryReply

    def reply(self) -> GeometryReply:
        return self.geometry


def run(rig: GeometryRig, request: GeometryRequest) -> GeometryResult:
    """The cell's parts in S from what is stored and configured; see the module doc."""
    del request  # nothing to ask: the cell as it is
    cfg = rig.sort_config or SortConfig()
    try:
        record = rig.store.read("system")
        calib = SystemCalibration.from_json(record.payload, source=str(record.path))
    except OmnisortError as exc:
        return GeometryResult(
            GeometryReply(cfg.cube_size_mm, problems=[f"no camera or laser plane: {exc}"])
        )
    corners = laser_patch(calib.laser_normal, calib.laser_distance_mm, LASER_PATCH_MM)
    calibrated = GeometryReply(
        cfg.cube_size_mm,
        camera_R_SC=np.round(calib.R_SC, 9).tolist(),
        laser_plane=LaserPlaneReply(
            normal=np.round(calib.laser_normal, 9).tolist(),
            distance_mm=round(float(calib.laser_distance_mm), 3),
            corners_S_mm=np.round(corners, 2).tolist(),
        ),
    )
    base = calib.robot_base
    if not isinstance(base, dict) or "matrix" not in base:
        problem = "robot not registered: no base, arm or bins"
        return GeometryResult(replace(calibrated, problems=[problem]))
    T_SB = np.asarray(base["matrix"], float)
    bins = []
    for spec in cfg.bins:
        rim, foot = bin_corners_B(spec)
        bins.append(BinReply(spec.color, _to_S(T_SB, rim), _to_S(T_SB, foot)))
    joints = rig.arm_joints()
    arm = None
    if joints is not None:
        arm = ArmReply(
            model=cfg.robot_model,
            joints_deg=[round(float(q), 4) for q in joints],
            points_S_mm=np.round(arm_points_S(cfg.robot_model, joints, T_SB), 2).tolist(),
        )
    registered = replace(
        calibrated,
        robot_base_T_SB=np.round(T_SB, 6).tolist(),
        floor_z_mm=round(float(T_SB[2, 3]), 2),
        bins=bins,
        arm=arm,
        problems=[] if arm is not None else ["no joint reading from the arm"],
    )
    return GeometryResult(registered)
