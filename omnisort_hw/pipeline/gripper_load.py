"""The gripper's load as state: whether it holds (or may hold) a cube, and what to do with it.

What is known comes from two places: the gripper itself (closed or open; its sensor, where it
has one: `holding` True/False, None when it cannot tell) and the job journal's cube in flight
(the pick in progress: its colour and bin). `assess` combines them for `status`;
`resolve_before_sort` is the first step of every `sort`: a held cube whose bin is known is
carried to that bin and released; a closed gripper that may hold an unknown object refuses
the sort (`gripper_loaded`) until an operator clears it (`reset` with `gripper_empty`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from omnisort_hw.core.pick_planning import tool_pose
from omnisort_hw.errors import OmnisortError
from omnisort_hw.pipeline.sort_report import CubeOutcome

if TYPE_CHECKING:
    from omnisort_hw.pipeline.sort import Sorter

log = logging.getLogger(__name__)


class InFlightJournal(Protocol):
    """The part of the job journal (`cell.journal.JobJournal`) a held cube needs: the cube in
    flight, and clearing it once its fate is known."""

    def in_flight(self) -> dict[str, Any] | None: ...

    def clear_in_flight(self, why: str) -> None: ...


class GripperLoadedError(OmnisortError):
    """The gripper holds or may hold an object the cell cannot place by itself."""

    code = "gripper_loaded"


@dataclass(frozen=True)
class GripperLoad:
    """`load`: empty, held (the sensor says so), maybe (closed, no sensor) or unknown."""

    load: str
    closed: bool | None
    sensor: bool | None
    cube: dict[str, Any] | None
    lost: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "load": self.load,
            "closed": self.closed,
            "sensor": self.sensor,
            "cube": self.cube,
            "lost": self.lost,
        }


def assess(arm: Any, in_flight: dict[str, Any] | None) -> GripperLoad:
    """The gripper's load now, from the device and the journal's cube in flight."""
    if arm is None or not getattr(arm, "is_connected", False):
        return GripperLoad("unknown", None, None, in_flight)
    try:
        grip = arm.gripper
        closed, sensor = bool(grip.is_closed), grip.holding
    except Exception as exc:
        log.warning("gripper state unreadable: %s", exc)
        return GripperLoad("unknown", None, None, in_flight)
    if sensor is True:
        return GripperLoad("held", closed, sensor, in_flight)
    if sensor is None and closed:
        return GripperLoad("maybe", closed, sensor, in_flight)
    # Open, or the sensor feels nothing: a cube recorded in flight is not in the gripper.
    lost = in_flight if in_flight and in_flight.get("phase") == "holding" else None
    return GripperLoad("empty", closed, sensor, None, lost)


def resolve_before_sort(
    sorter: Sorter, journal: InFlightJournal, T_SB: np.ndarray
) -> CubeOutcome | None:
    """Place the cube the gripper holds in its bin before anything else moves; None when the
    gripper is empty. Raises GripperLoadedError when the load cannot be placed."""
    arm = sorter._require_arm()
    state = assess(arm, journal.in_flight())
    if state.load == "empty":
        if state.lost is not None:
            journal.clear_in_flight(f"gripper empty at the next sort; cube {state.lost} lost")
        return None
    cube = state.cube
    bin_spec = sorter.cfg.bin_for(cube["color"]) if cube and cube.get("color") else None
    if state.load == "unknown" or cube is None or bin_spec is None:
        what = f"a {cube['color']} cube" if cube else "an unknown object"
        raise GripperLoadedError(
            f"sort refused: the gripper is closed and may hold {what} "
            f"(sensor: {state.sensor}); remove it by hand, then send reset with "
            "gripper_empty=true"
        )
    sorter.calibration.check_motion_allowed()
    arm.safety_status().raise_if_stopped(arm.name)
    nan = [math.nan] * 3
    out = CubeOutcome(
        cube.get("cube", -1),
        cube["color"],
        nan,
        nan,
        math.nan,
        math.nan,
        "failed",
        f"held from {cube.get('job', 'an earlier job')}",
        bin_spec.color,
    )
    planner = sorter._planner(T_SB)
    q = np.asarray(arm.joint_positions(), float)
    moves = []
    cfg = sorter.cfg
    lift_z = cfg.floor_z_B_mm + cfg.cube_size_mm / 2.0 + cfg.grasp_above_center_mm + cfg.lift_mm
    T = np.asarray(arm.tcp_pose(), float)
    if T[2, 3] < lift_z:
        T_up = T.copy()
        T_up[2, 3] = lift_z
        lift = planner.plan_linear(
            q, T_up, planner.static, "lift the held cube", holding=True, held_on_floor=True
        )
        moves.append(lift)
        q = lift.q_target
    release, bin_yaw = planner.release_point(bin_spec)
    yaw = math.degrees(math.atan2(T[1, 0], T[0, 0]))
    base = bin_yaw + 90.0 * round((yaw - bin_yaw) / 90.0)
    poses = [tool_pose(release, base + d) for d in (0.0, 90.0, -90.0, 180.0)]
    moves += planner.path_to_any(q, poses, planner.static, "carry the held cube to its bin")
    log.warning("placing the held %s cube in its bin before sorting", cube["color"])
    sorter.log.event("sorting/held_cube", f"{cube} -> bin {bin_spec.color}", level="WARN")
    for move in moves:
        sorter._send(move)
    arm.gripper.open()
    journal.clear_in_flight(f"placed in bin {bin_spec.color}")
    out.status = "sorted"
    out.planned_motion_s = float(sum(m.traj.duration for m in moves))
    sorter._go_home(planner)
    return out
