"""The virtual cell's control channel: the simulator's own controls, one JSON object per line in
and one out (`{"ok": true, "result": {...}}` or `{"ok": false, "error": "..."}`).

It is what the simulator's panel (`omnisort ui` with `[ui] sim_control`) and the tests use to
do what a person or the world would do to a real cell: hold a board, knock the camera, move a
cube, jog the arm from the pendant, drop a connection. The service never uses it: it only
sees the cell through the real protocols. `COMMANDS` is the one list of the commands and their
arguments; docs/virtual_cell.md shows it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.errors import MotionRefusedError
from sim_backend.scene_images import write_render
from sim_backend.virtual_cell.held_board import HELD_VIEWS, check_view
from sim_backend.virtual_cell.servers import all_status

FACES = ("arm", "dashboard", "laser", "camera")
MOVE_TIMEOUT_S = 120.0

COMMANDS: dict[str, str] = {
    "status": "the controller's modes, the laser, renders, late ticks",
    "truth": "cube poses in S, the bin each is in, collisions, the camera's rotation and the "
    "laser plane as system.json holds them, the joints and the gripper",
    "protective_stop": "a protective stop, as a safety sensor triggers it",
    "emergency_stop": "an emergency stop",
    "release_emergency_stop": "the emergency stop button pulled out again",
    "drop": "`what` = arm, dashboard, laser, camera or all: its connections closed",
    "stall": "`what`, `seconds`: that face stops answering for a while",
    "unstall": "`what`: that face answers again",
    "board": "`view` = 0..11 or null: a checkerboard held in front of the camera (one of 12 "
    "poses covering the field), or put down",
    "camera": "`roll_deg`, `pitch_deg`, `yaw_deg`: the camera mounted at these angles",
    "knock": "`angle_deg`, `axis` (x, y, z or a vector of S): the camera turned from where it is",
    "laser": "`on`, `roll_deg`, `pitch_deg`, `distance_mm` (each optional): the emitter "
    "switched, turned and moved",
    "target": "`on` (default true), `kind` (two_sided or three_sided), `x_mm`, `y_mm`, "
    "`yaw_deg` (its centre on the floor, in S; each optional): the calibration target put "
    "in the cell, changed, moved, or taken away",
    "cube": "`action` = move (`index`, `x_mm`, `y_mm`, `yaw_deg`: put down there, in S), add "
    "(`color`, `x_mm`, `y_mm`, `yaw_deg`) or remove (`index`)",
    "joints": "`q_deg` (6): the arm jogged there from the pendant; returns once it stands",
    "move_to": "`x_mm`, `y_mm`, `z_mm` of the robot base: the tool moved there, turned as it "
    "is, through the core's inverse kinematics; returns once it stands",
    "gripper": "`closed`: the gripper closed (on the cube between its fingers) or opened",
    "render": "`folder` (and `name`): the picture as it is now and the renderer's truth beside "
    "it (NAME.png, NAME.truth.json); with `views` (a list of board poses) one pair per "
    "held board instead, the dataset of the intrinsics",
}

# The calls that change the picture return once a picture shows the change.
SHOWN_TIMEOUT_S = 60.0


def _number(req: dict[str, Any], key: str) -> float | None:
    """The request's number `key`, None when it is not given."""
    value = req.get(key)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise ValueError(f"{key} must be a number, got {value!r}")
    return float(value)


def _number_or(req: dict[str, Any], key: str, default: float) -> float:
    """The request's number `key`, `default` when it is not given."""
    value = _number(req, key)
    return default if value is None else value


def _required(req: dict[str, Any], key: str) -> float:
    value = _number(req, key)
    if value is None:
        raise ValueError(f"{key} is required")
    return value


class ControlChannel:
    """The commands of `COMMANDS` on one virtual cell; `execute(request) -> result` raises
    ValueError (the reply's error) on a bad or refused request."""

    def __init__(self, vc: Any) -> None:
        self.vc = vc  # the `cell.VirtualCell` it belongs to (which builds this channel)
        self._renders = 0
        self._handlers: dict[str, Callable[[dict[str, Any]], dict[str, Any]]] = {
            name: getattr(self, f"_{name}") for name in COMMANDS
        }

    def execute(self, req: dict[str, Any]) -> dict[str, Any]:
        cmd = req.get("cmd")
        handler = self._handlers.get(cmd) if isinstance(cmd, str) else None
        if handler is None:
            raise ValueError(f"unknown command {cmd!r} (known: {', '.join(COMMANDS)})")
        try:
            return handler(req)
        except MotionRefusedError as exc:
            raise ValueError(str(exc)) from exc

    # ---- the cell's state ---------------------------------------------------------------------

    def _status(self, req: dict[str, Any]) -> dict[str, Any]:
        vc = self.vc
        return {
            **all_status(vc.ctl),
            "laser_on": bool(vc.cell.world.laser_on),
            "camera_renders": vc.frames.renders,
            "late_ticks": vc.late_ticks,
            "rtde_packages_sent": vc.rtde.sent,
        }

    def _truth(self, req: dict[str, Any]) -> dict[str, Any]:
        return self.vc.truth()

    # ---- safety and faults ---------------------------------------------------------------------

    def _protective_stop(self, req: dict[str, Any]) -> dict[str, Any]:
        self.vc.ctl.protective_stop()
        return {}

    def _emergency_stop(self, req: dict[str, Any]) -> dict[str, Any]:
        self.vc.ctl.emergency_stop()
        return {}

    def _release_emergency_stop(self, req: dict[str, Any]) -> dict[str, Any]:
        self.vc.ctl.release_emergency_stop()
        return {}

    def _faces(self, req: dict[str, Any]) -> tuple[str, ...]:
        what = req.get("what", "arm")
        if what not in (*FACES, "all"):
            raise ValueError(f"what must be one of {', '.join(FACES)} or all")
        return FACES if what == "all" else (what,)

    def _drop(self, req: dict[str, Any]) -> dict[str, Any]:
        vc, closed = self.vc, 0
        for face in self._faces(req):
            if face == "arm":
                closed += vc.rtde.listener.drop() + vc.script.listener.drop()
            elif face == "dashboard":
                closed += vc.dashboard.listener.drop()
            elif face == "camera":
                closed += vc.camera.listener.drop()
            else:
                vc.laser.drop()
        return {"closed": closed}

    def _stall(self, req: dict[str, Any]) -> dict[str, Any]:
        seconds = _number_or(req, "seconds", 3600.0)
        for face in self._faces(req):
            self.vc.faults.stall(face, seconds)
        return {}

    def _unstall(self, req: dict[str, Any]) -> dict[str, Any]:
        for face in self._faces(req):
            self.vc.faults.clear(face)
        return {}

    # ---- what the camera sees -------------------------------------------------------------------

    def _shown(self) -> bool:
        return self.vc.frames.wait_shown(SHOWN_TIMEOUT_S)

    def _board(self, req: dict[str, Any]) -> dict[str, Any]:
        view = check_view(req.get("view"))
        shown = self.vc.frames.hold_board(view, SHOWN_TIMEOUT_S)
        return {"view": view, "views": HELD_VIEWS, "shown": shown}

    def _camera(self, req: dict[str, Any]) -> dict[str, Any]:
        R = self.vc.cell.mount_camera(
            _number_or(req, "roll_deg", 0.0),
            _number_or(req, "pitch_deg", 0.0),
            _number_or(req, "yaw_deg", 0.0),
        )
        return {"R_SC": R.tolist(), "shown": self._shown()}

    def _knock(self, req: dict[str, Any]) -> dict[str, Any]:
        R = self.vc.cell.bump_camera(_number_or(req, "angle_deg", 0.5), req.get("axis", "x"))
        return {"R_SC": R.tolist(), "shown": self._shown()}

    def _laser(self, req: dict[str, Any]) -> dict[str, Any]:
        cell = self.vc.cell
        on = req.get("on")
        if on is not None and not isinstance(on, bool):
            raise ValueError(f"on must be true or false, got {on!r}")
        cell.set_laser_plane(
            _number(req, "roll_deg"), _number(req, "pitch_deg"), _number(req, "distance_mm")
        )
        if on is not None:
            with cell.lock:
                cell.world.laser_on = on
        return {"laser_plane": self.vc.truth()["laser_plane"], "shown": self._shown()}

    def _target(self, req: dict[str, Any]) -> dict[str, Any]:
        on = req.get("on", True)
        kind = req.get("kind")
        if not isinstance(on, bool) or (kind is not None and not isinstance(kind, str)):
            raise ValueError(f"on must be true or false and kind a name, got {on!r}, {kind!r}")
        x, y = _number(req, "x_mm"), _number(req, "y_mm")
        if (x is None) != (y is None):
            raise ValueError("x_mm and y_mm go together: the target's centre on the floor")
        self.vc.cell.set_target(
            on, kind, None if x is None or y is None else (x, y), _number(req, "yaw_deg")
        )
        return {"target": self.vc.truth()["target"], "shown": self._shown()}

    def _cube(self, req: dict[str, Any]) -> dict[str, Any]:
        cell, action = self.vc.cell, req.get("action")
        index = req.get("index")
        if action == "move":
            cell.place_cube(
                index,
                _required(req, "x_mm"),
                _required(req, "y_mm"),
                _number_or(req, "yaw_deg", 0.0),
            )
        elif action == "add":
            index = cell.add_cube(
                str(req.get("color", "")),
                _required(req, "x_mm"),
                _required(req, "y_mm"),
                _number_or(req, "yaw_deg", 0.0),
            )
        elif action == "remove":
            cell.remove_cube(index, held=self.vc.arm.gripper.held_body)
        else:
            raise ValueError(f"action must be move, add or remove, got {action!r}")
        return {"index": index, "cubes": self.vc.truth()["cubes"], "shown": self._shown()}

    # ---- the arm from the pendant ----------------------------------------------------------------

    def _stand(self, started: dict[str, Any]) -> dict[str, Any]:
        """Wait for the pendant's move to end (bounded), then for a picture of it."""
        ctl = self.vc.ctl
        deadline = time.monotonic() + started["seconds"] + MOVE_TIMEOUT_S
        while ctl.moving:
            if time.monotonic() > deadline:
                raise ValueError("the arm did not come to rest")
            time.sleep(0.02)
        return {**started, "joints_deg": np.rad2deg(ctl.q).tolist(), "shown": self._shown()}

    def _joints(self, req: dict[str, Any]) -> dict[str, Any]:
        q = req.get("q_deg")
        if (
            not isinstance(q, list)
            or len(q) != 6
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in q)
            or not np.all(np.isfinite(q))
        ):
            raise ValueError(f"q_deg must be 6 joint angles in degrees, got {q!r}")
        return self._stand(self.vc.ctl.pendant_move(q_deg=np.asarray(q, float)))

    def _move_to(self, req: dict[str, Any]) -> dict[str, Any]:
        xyz = np.array([_required(req, k) for k in ("x_mm", "y_mm", "z_mm")])
        return self._stand(self.vc.ctl.pendant_move(xyz_mm=xyz))

    def _gripper(self, req: dict[str, Any]) -> dict[str, Any]:
        closed = req.get("closed")
        if not isinstance(closed, bool):
            raise ValueError(f"closed must be true or false, got {closed!r}")
        vc = self.vc
        if vc.ctl.moving:
            raise ValueError("the arm is moving: wait for it to stop")
        with vc.ctl.lock:
            if closed:
                vc.arm.gripper.close()
            else:
                vc.arm.gripper.open()
        return {
            "closed": closed,
            "holding": vc.arm.gripper.held_body is not None,
            "shown": self._shown(),
        }

    # ---- pictures and their truth -----------------------------------------------------------

    def _render(self, req: dict[str, Any]) -> dict[str, Any]:
        folder = req.get("folder")
        if not isinstance(folder, str) or not folder:
            raise ValueError("folder is required: where the pictures and their truth go")
        out = Path(folder).expanduser()
        views = req.get("views")
        frames = self.vc.frames
        written: list[str] = []
        try:
            if views is None:
                name = req.get("name")
                if name is None:
                    self._renders += 1
                    name = f"render_{self._renders:03d}"
                if (
                    not isinstance(name, str)
                    or not name.replace("_", "").replace("-", "").isalnum()
                ):
                    raise ValueError(f"name must be letters, digits, - and _, got {name!r}")
                image, truth = frames.snapshot()
                written.append(str(write_render(out, name, image, truth)[0]))
            else:
                if not isinstance(views, list) or not views:
                    raise ValueError(f"views must be a list of board poses, got {views!r}")
                poses = [check_view(v) for v in views if v is not None]
                if len(poses) != len(views):
                    raise ValueError("views: each must be a board pose, not null")
                held = frames.board
                try:
                    for k in poses:
                        frames.board = k
                        image, truth = frames.snapshot()
                        written.append(str(write_render(out, f"board_{k:02d}", image, truth)[0]))
                finally:
                    frames.board = held
        except (OSError, RuntimeError) as exc:
            raise ValueError(f"render into {out}: {exc}") from exc
        return {"folder": str(out), "images": written}
