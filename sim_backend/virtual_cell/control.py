"""The virtual cell's control channel: the simulator's own controls, one JSON object per line in
and one out (`{"ok": true, "result": {...}}` or `{"ok": false, "error": "..."}`).

It is what the simulator's panel (`omnisort ui` with `[ui] sim_control`) and the tests use to
do what a person or the world would do to a real cell: hold a board, knock the camera, move a
cube, jog the arm from the pendant, drop a connection. The service never uses it: it only
sees the cell through the real protocols. Its commands and their arguments are declared once,
in `omnisort_hw.sim_requests` (`describe` gives their JSON Schema; docs/virtual_cell.md lists
them): each request is checked against its declaration, then handled as its record.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw import sim_requests as sr
from omnisort_hw.errors import MotionRefusedError
from omnisort_hw.sim_replies import (
    SimArmStood,
    SimBoardHeld,
    SimCameraTurned,
    SimCubesSet,
    SimDescription,
    SimDone,
    SimDropped,
    SimGripperSet,
    SimLaserSet,
    SimRendered,
    SimTargetSet,
)
from omnisort_hw.wire_records import to_wire
from sim_backend.scene_images import write_render
from sim_backend.virtual_cell.held_board import HELD_VIEWS
from sim_backend.virtual_cell.servers import all_status

FACES = tuple(f for f in sr.FACES if f != "all")  # each face "all" names
MOVE_TIMEOUT_S = 120.0

# The calls that change the picture return once a picture shows the change.
SHOWN_TIMEOUT_S = 60.0


class ControlChannel:
    """The commands of `sim_requests.SIM_COMMANDS` on one virtual cell; `execute(request) ->
    result` raises ValueError (the reply's error) on a bad or refused request."""

    def __init__(self, vc: Any) -> None:
        self.vc = vc  # the `cell.VirtualCell` it belongs to (which builds this channel)
        self._renders = 0
        self._handlers: dict[str, Callable[[Any], object]] = {
            name: getattr(self, f"_{name}") for name in sr.SIM_COMMANDS
        }

    def execute(self, req: dict[str, Any]) -> dict[str, Any]:
        """The request's reply record (`SIM_COMMANDS` names each command's) as JSON."""
        cmd, request = sr.validate(req)
        try:
            reply: dict[str, Any] = to_wire(self._handlers[cmd](request))
            return reply
        except MotionRefusedError as exc:
            raise ValueError(str(exc)) from exc

    # ---- the cell's state ---------------------------------------------------------------------

    def _describe(self, req: sr.DescribeRequest) -> SimDescription:
        return sr.describe_sim()

    def _status(self, req: sr.NoArgs) -> dict[str, Any]:
        vc = self.vc
        return {
            **all_status(vc.ctl),
            "laser_on": bool(vc.cell.world.laser_on),
            "camera_renders": vc.frames.renders,
            "late_ticks": vc.late_ticks,
            "rtde_packages_sent": vc.rtde.sent,
        }

    def _truth(self, req: sr.TruthRequest) -> dict[str, Any]:
        return self.vc.truth()

    # ---- safety and faults ---------------------------------------------------------------------

    def _protective_stop(self, req: sr.NoArgs) -> SimDone:
        self.vc.ctl.protective_stop()
        return SimDone()

    def _emergency_stop(self, req: sr.NoArgs) -> SimDone:
        self.vc.ctl.emergency_stop()
        return SimDone()

    def _release_emergency_stop(self, req: sr.NoArgs) -> SimDone:
        self.vc.ctl.release_emergency_stop()
        return SimDone()

    @staticmethod
    def _faces(what: str) -> tuple[str, ...]:
        return FACES if what == "all" else (what,)

    def _drop(self, req: sr.DropRequest) -> SimDropped:
        vc, closed = self.vc, 0
        for face in self._faces(req.what):
            if face == "arm":
                closed += vc.rtde.listener.drop() + vc.script.listener.drop()
            elif face == "dashboard":
                closed += vc.dashboard.listener.drop()
            elif face == "camera":
                closed += vc.camera.listener.drop()
            else:
                vc.laser.drop()
        return SimDropped(closed)

    def _stall(self, req: sr.StallRequest) -> SimDone:
        for face in self._faces(req.what):
            self.vc.faults.stall(face, req.seconds)
        return SimDone()

    def _unstall(self, req: sr.UnstallRequest) -> SimDone:
        for face in self._faces(req.what):
            self.vc.faults.clear(face)
        return SimDone()

    # ---- what the camera sees -------------------------------------------------------------------

    def _shown(self) -> bool:
        return self.vc.frames.wait_shown(SHOWN_TIMEOUT_S)

    def _board(self, req: sr.BoardRequest) -> SimBoardHeld:
        shown = self.vc.frames.hold_board(req.view, SHOWN_TIMEOUT_S)
        return SimBoardHeld(view=req.view, views=HELD_VIEWS, shown=shown)

    def _camera(self, req: sr.CameraRequest) -> SimCameraTurned:
        R = self.vc.cell.mount_camera(req.roll_deg, req.pitch_deg, req.yaw_deg)
        return SimCameraTurned(R_SC=R.tolist(), shown=self._shown())

    def _knock(self, req: sr.KnockRequest) -> SimCameraTurned:
        R = self.vc.cell.bump_camera(req.angle_deg, req.axis)
        return SimCameraTurned(R_SC=R.tolist(), shown=self._shown())

    def _laser(self, req: sr.LaserRequest) -> SimLaserSet:
        cell = self.vc.cell
        cell.set_laser_plane(req.roll_deg, req.pitch_deg, req.distance_mm)
        if req.on is not None:
            with cell.lock:
                cell.world.laser_on = req.on
        return SimLaserSet(laser_plane=self.vc.truth()["laser_plane"], shown=self._shown())

    def _target(self, req: sr.TargetRequest) -> SimTargetSet:
        x, y = req.x_mm, req.y_mm
        self.vc.cell.set_target(
            req.on,
            sr.SCENE_TARGETS[req.kind] if req.kind is not None else None,
            None if x is None or y is None else (x, y),
            req.yaw_deg,
        )
        return SimTargetSet(target=self.vc.truth()["target"], shown=self._shown())

    def _cube(self, req: sr.CubeRequest) -> SimCubesSet:
        cell, index, yaw = self.vc.cell, req.index, req.yaw_deg or 0.0
        if req.action == "move":
            assert index is not None and req.x_mm is not None and req.y_mm is not None
            cell.place_cube(index, req.x_mm, req.y_mm, yaw)
        elif req.action == "add":
            assert req.color is not None and req.x_mm is not None and req.y_mm is not None
            index = cell.add_cube(req.color, req.x_mm, req.y_mm, yaw)
        else:
            cell.remove_cube(index, held=self.vc.arm.gripper.held_body)
        return SimCubesSet(index=index, cubes=self.vc.truth()["cubes"], shown=self._shown())

    # ---- the arm from the pendant ----------------------------------------------------------------

    def _stand(self, started: dict[str, Any]) -> SimArmStood:
        """Wait for the pendant's move to end (bounded), then for a picture of it."""
        ctl = self.vc.ctl
        deadline = time.monotonic() + started["seconds"] + MOVE_TIMEOUT_S
        while ctl.moving:
            if time.monotonic() > deadline:
                raise ValueError("the arm did not come to rest")
            time.sleep(0.02)
        joints = np.rad2deg(ctl.q).tolist()
        return SimArmStood(**started, joints_deg=joints, shown=self._shown())

    def _joints(self, req: sr.JointsRequest) -> SimArmStood:
        return self._stand(self.vc.ctl.pendant_move(q_deg=np.asarray(req.q_deg, float)))

    def _move_to(self, req: sr.MoveToRequest) -> SimArmStood:
        xyz = np.array([req.x_mm, req.y_mm, req.z_mm])
        return self._stand(self.vc.ctl.pendant_move(xyz_mm=xyz))

    def _gripper(self, req: sr.GripperRequest) -> SimGripperSet:
        vc = self.vc
        if vc.ctl.moving:
            raise ValueError("the arm is moving: wait for it to stop")
        with vc.ctl.lock:
            if req.closed:
                vc.arm.gripper.close()
            else:
                vc.arm.gripper.open()
        holding = vc.arm.gripper.held_body is not None
        return SimGripperSet(closed=req.closed, holding=holding, shown=self._shown())

    # ---- pictures and their truth -----------------------------------------------------------

    def _render(self, req: sr.RenderRequest) -> SimRendered:
        out = Path(req.folder).expanduser()
        frames = self.vc.frames
        written: list[str] = []
        try:
            if not req.views:
                name = req.name
                if name is None:
                    self._renders += 1
                    name = f"render_{self._renders:03d}"
                if not name.replace("_", "").replace("-", "").isalnum():
                    raise ValueError(f"name must be letters, digits, - and _, got {name!r}")
                image, truth = frames.snapshot()
                written.append(str(write_render(out, name, image, truth)[0]))
            else:
                held = frames.board
                try:
                    for k in range(HELD_VIEWS):
                        frames.board = k
                        image, truth = frames.snapshot()
                        written.append(str(write_render(out, f"board_{k:02d}", image, truth)[0]))
                finally:
                    frames.board = held
        except (OSError, RuntimeError) as exc:
            raise ValueError(f"render into {out}: {exc}") from exc
        return SimRendered(str(out), written)
