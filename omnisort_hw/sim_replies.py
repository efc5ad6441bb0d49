"""The control channel's replies the Simulator tab reads, as typed records read by the
replies' codec (`wire_records.from_wire`), so that the tab reads fields, not keys:
- `truth`: what the virtual cell's renderer and physics hold (the camera's mounting, the laser,
  the target, the cubes, the arm); the virtual cell writes it
  (`sim_backend.virtual_cell.cell.VirtualCell.truth`) with more than the tab reads, and a test
  holds the two together;
- `describe`: each command's help and its arguments' JSON Schema (`sim_requests.describe_sim`
  writes it);
- what each control did (`SimDone`, `SimBoardHeld`, ...: `sim_requests.SIM_COMMANDS` names
  each command's), with whether a picture shows it yet (`SimShown.shown`).
Lengths in mm, angles in degrees, points in S (cubes, target) or B (tool)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from omnisort_hw.wire_records import wire_key


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


@dataclass(frozen=True, kw_only=True)
class SimTruth:
    """The virtual cell as its simulator holds it."""

    camera: CameraTruth = wire_key("camera_rotation")
    laser: LaserTruth = wire_key("laser_plane")
    laser_on: bool
    target: TargetTruth | None  # None: taken away
    cubes: tuple[CubeTruth, ...]
    joints_deg: tuple[float, ...]
    tcp_B_mm: tuple[float, float, float]
    gripper_closed: bool
    held: bool
    collisions: list[str]  # what touched what, so far


@dataclass(frozen=True)
class SimCommandDescription:
    """A control-channel command as `describe` gives it: its help and its arguments' JSON
    Schema (draft 2020-12)."""

    help: str
    args: dict[str, Any]


@dataclass(frozen=True)
class SimDescription:
    """The channel's `describe`: every command by name."""

    commands: dict[str, SimCommandDescription]


Record = dict[str, Any]
"""A record as the simulator keeps it (the laser plane and the target as system.json holds
them, a cube's truth)."""


@dataclass(frozen=True)
class SimDone:
    """A control that changes nothing a picture shows (a stop, a stall, its end)."""


@dataclass(frozen=True)
class SimDropped:
    """`drop`: how many connections were closed."""

    closed: int


@dataclass(frozen=True, kw_only=True)
class SimShown:
    """A control that changes the picture: whether a picture shows the change yet (False:
    none did within its time)."""

    shown: bool


@dataclass(frozen=True, kw_only=True)
class SimBoardHeld(SimShown):
    """`board`: the pose held (None: put down) of the HELD_VIEWS poses."""

    view: int | None
    views: int


@dataclass(frozen=True, kw_only=True)
class SimCameraTurned(SimShown):
    """`camera` and `knock`: the camera's rotation in S now."""

    R_SC: list[list[float]]


@dataclass(frozen=True, kw_only=True)
class SimLaserSet(SimShown):
    """`laser`: the laser plane now."""

    laser_plane: Record


@dataclass(frozen=True, kw_only=True)
class SimTargetSet(SimShown):
    """`target`: the target now (None: taken away)."""

    target: Record | None


@dataclass(frozen=True, kw_only=True)
class SimCubesSet(SimShown):
    """`cube`: the cube moved, added or removed, and every cube now."""

    index: int | None
    cubes: list[Record]


@dataclass(frozen=True, kw_only=True)
class SimArmStood(SimShown):
    """`joints` and `move_to`: the pendant's target, the move's time, the joints at rest."""

    q_deg: list[float]
    seconds: float
    joints_deg: list[float]


@dataclass(frozen=True, kw_only=True)
class SimGripperSet(SimShown):
    """`gripper`: closed or open, and whether it holds a cube."""

    closed: bool
    holding: bool


@dataclass(frozen=True)
class SimRendered:
    """`render`: the folder and the images written there."""

    folder: str
    images: list[str]
