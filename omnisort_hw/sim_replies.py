"""The control channel's `truth` reply as typed records: what the virtual cell's renderer and
physics hold (the camera's mounting, the laser, the target, the cubes, the arm), read once
from the wire (`SimTruth.from_wire`), so that the Simulator tab reads fields, not keys. The
virtual cell writes the reply (`sim_backend.virtual_cell.cell.VirtualCell.truth`); a test holds
the two together. Lengths in mm, angles in degrees, points in S (cubes, target) or B (tool)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class CameraTruth:
    """The camera's rotation in S as it is now (mounted, or knocked)."""

    roll_deg: float
    pitch_deg: float
    yaw_deg: float


@dataclass(frozen=True)
class LaserTruth:
    """The laser plane as it is now: its angles and its distance below the camera."""

    roll_deg: float
    pitch_deg: float
    distance_mm: float


@dataclass(frozen=True)
class TargetTruth:
    """The calibration target: its kind as the channel names it, its centre on the floor of S
    and its turn about the vertical."""

    kind: str
    center_mm: tuple[float, float]
    yaw_deg: float


@dataclass(frozen=True)
class CubeTruth:
    """A cube: its index (what `cube` names), colour, centre in S and the bin that holds it."""

    index: int
    color: str
    center_S_mm: tuple[float, float, float]
    bin: str | None


@dataclass(frozen=True)
class SimTruth:
    """The virtual cell as its simulator holds it."""

    camera: CameraTruth
    laser: LaserTruth
    laser_on: bool
    target: TargetTruth | None  # None: taken away
    cubes: tuple[CubeTruth, ...]
    joints_deg: tuple[float, ...]
    tcp_B_mm: tuple[float, float, float]
    gripper_closed: bool
    held: bool
    collisions: int

    @classmethod
    def from_wire(cls, d: Mapping[str, Any]) -> SimTruth:
        """The `truth` reply's JSON object as records (KeyError naming a missing key)."""
        cam, las, target = d["camera_rotation"], d["laser_plane"], d.get("target")
        return cls(
            camera=CameraTruth(
                float(cam["roll_deg"]), float(cam["pitch_deg"]), float(cam["yaw_deg"])
            ),
            laser=LaserTruth(
                float(las["roll_deg"]), float(las["pitch_deg"]), float(las["distance_mm"])
            ),
            laser_on=bool(d["laser_on"]),
            target=None
            if target is None
            else TargetTruth(
                str(target["kind"]),
                (float(target["center_mm"][0]), float(target["center_mm"][1])),
                float(target["yaw_deg"]),
            ),
            cubes=tuple(
                CubeTruth(
                    int(c["index"]),
                    str(c["color"]),
                    (
                        float(c["center_S_mm"][0]),
                        float(c["center_S_mm"][1]),
                        float(c["center_S_mm"][2]),
                    ),
                    c.get("bin") or None,
                )
                for c in d["cubes"]
            ),
            joints_deg=tuple(float(q) for q in d["joints_deg"]),
            tcp_B_mm=(float(d["tcp_B_mm"][0]), float(d["tcp_B_mm"][1]), float(d["tcp_B_mm"][2])),
            gripper_closed=bool(d["gripper_closed"]),
            held=bool(d["held"]),
            collisions=len(d.get("collisions") or ()),
        )
