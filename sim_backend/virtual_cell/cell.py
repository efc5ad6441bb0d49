"""One virtual cell: the pybullet world of a scene behind the real protocols, in one process.

    cell = VirtualCell("sorting", "127.0.0.2", width=960)
    cell.start()                       # every port accepts when this returns
    ...
    cell.close()                       # ordered: servers, tick, renderer, pybullet

Faces on `host` (the ports are a UR controller's, so parallel cells need distinct loopback
addresses): RTDE 30004, dashboard 29999, script port 30003, the laser's Modbus TCP 5020, the
camera's MJPEG stream 8080 and the control channel 30111 (one JSON object per line; its
commands are `omnisort_hw.sim_requests.SIM_COMMANDS`: faults, the board held for the
intrinsics, the camera's mounting and knocks, the laser, the cubes, the arm from the pendant,
renders with truth).
"""

from __future__ import annotations

import contextlib
import json
import logging
import socket
import threading
import time
from typing import Any

import numpy as np

from omnisort_hw.sim_requests import SCENE_TARGETS
from sim_backend.devices import SimArm, SimCell
from sim_backend.scene import load_scene, with_camera_effects
from sim_backend.sort_harness import SimVerifier
from sim_backend.truth import mounting_truth
from sim_backend.virtual_cell.camera_stream import (
    CAMERA_PORT,
    CameraStreamServer,
    FrameSource,
    target_pose,
)
from sim_backend.virtual_cell.control import ControlChannel
from sim_backend.virtual_cell.controller import RATE_HZ, URController
from sim_backend.virtual_cell.laser_modbus import MODBUS_PORT, LaserModbusServer
from sim_backend.virtual_cell.servers import (
    DASHBOARD_PORT,
    RTDE_PORT,
    SCRIPT_PORT,
    DashboardServer,
    Faults,
    Listener,
    RTDEServer,
    ScriptServer,
    serve_lines,
)

log = logging.getLogger("virtual_cell")

CONTROL_PORT = 30111


class VirtualCell:
    """The simulated cell of `scene` served on `host`; see the module docstring."""

    def __init__(
        self,
        scene: str,
        host: str,
        *,
        width: int | None = None,
        height: int | None = None,
        seed: int = 0,
        fps: float = 10.0,
        unlock_delay_s: float = 5.0,
        gripper_output: tuple[str, int] = ("tool", 0),
        degraded: bool = False,
        effects: bool = False,
    ) -> None:
        self.host = host
        size: dict[str, Any] = {
            k: v for k, v in (("width", width), ("height", height or width)) if v
        }
        spec = load_scene(scene)
        self.cell = SimCell.from_scene(
            with_camera_effects(spec) if effects else spec, seed=seed, **size
        )
        self.arm = SimArm(self.cell)
        self.arm.connect()
        self.verifier = SimVerifier(self.arm)
        self.verifier.on_located()
        self.verifier.start()
        self.ctl = URController(self.arm, gripper_output, unlock_delay_s)
        self.faults = Faults()
        self.rtde = RTDEServer(host, self.ctl, self.faults)
        self.dashboard = DashboardServer(host, self.ctl, self.faults)
        self.script = ScriptServer(host, self.ctl, self.faults)
        self.laser = LaserModbusServer(host, self.cell, self.faults)
        self.frames = FrameSource(self.cell, self.ctl, scene, seed, degraded or effects, effects)
        self.camera = CameraStreamServer(host, self.frames, self.faults, fps=fps)
        self.control = Listener(host, CONTROL_PORT, self._control, "control")
        self.channel = ControlChannel(self)
        self._stop = threading.Event()
        self._tick = threading.Thread(target=self._run_tick, name="controller-tick", daemon=True)
        self.late_ticks = 0

    @property
    def ports(self) -> dict[str, int]:
        return {
            "rtde": RTDE_PORT,
            "dashboard": DASHBOARD_PORT,
            "script": SCRIPT_PORT,
            "laser": MODBUS_PORT,
            "camera": CAMERA_PORT,
            "control": CONTROL_PORT,
        }

    def start(self, timeout_s: float = 60.0) -> None:
        """Start every face and the tick; return once every port accepts a connection."""
        self._tick.start()
        for listener in (
            self.rtde.listener,
            self.dashboard.listener,
            self.script.listener,
            self.camera.listener,
            self.control,
        ):
            listener.start()
        self.laser.start()
        self.frames.start(timeout_s)
        deadline = time.monotonic() + timeout_s
        for port in self.ports.values():
            while True:
                try:
                    with socket.create_connection((self.host, port), timeout=1.0):
                        break
                except OSError:
                    if time.monotonic() > deadline:
                        raise RuntimeError(f"{self.host}:{port} does not accept") from None
                    time.sleep(0.05)

    def _run_tick(self) -> None:
        period = 1.0 / RATE_HZ
        next_t = time.monotonic()
        while not self._stop.is_set():
            try:
                self.ctl.tick()
            except Exception:
                log.exception("controller tick failed")
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                self.late_ticks += 1
                if delay < -0.1:
                    next_t = time.monotonic()

    # ---- control channel --------------------------------------------------------------------

    def truth(self) -> dict[str, Any]:
        """Where every cube is (S, mm), which bin holds it, the collisions so far, and the
        camera's rotation and the laser plane (as system.json holds them)."""
        cubes = []
        for c in self.verifier.true_cubes():
            cubes.append(
                {
                    "index": c.index,
                    "color": c.color,
                    "center_S_mm": [float(v) for v in c.center_S],
                    "bin": self.verifier.bin_of(c.center_S),
                }
            )
        world = self.cell.world
        T = world.T_S_B
        return {
            **mounting_truth(world, bool(world.laser_on)),
            "cubes": cubes,
            "collisions": list(self.verifier.collisions),
            "T_S_B": np.asarray(T).tolist() if T is not None else None,
            "held": self.arm.gripper.held_body is not None,
            "gripper_closed": self.arm.gripper.is_closed,
            "joints_deg": np.rad2deg(self.ctl.q).tolist(),
            "tcp_B_mm": world.tcp_pose_B()[:3, 3].tolist(),
            "target": _contract_names(target_pose(world.target_spec)),
            "laser_on": bool(self.cell.world.laser_on),
        }

    def command(self, req: dict[str, Any]) -> dict[str, Any]:
        """One control-channel request -> its result (raises ValueError on a bad request)."""
        return self.channel.execute(req)

    def _control(self, sock: socket.socket) -> None:
        def reply(line: str) -> str:
            try:
                answer = {"ok": True, "result": self.command(json.loads(line))}
            except (ValueError, TypeError, AttributeError) as exc:
                answer = {"ok": False, "error": str(exc)}
            return json.dumps(answer)

        serve_lines(sock, self.control.stop, reply)

    # ---- shutdown ---------------------------------------------------------------------------

    def close(self) -> None:
        """Ordered stop: clients' faces first, then the tick, the renderer and pybullet."""
        for listener in (
            self.control,
            self.camera.listener,
            self.script.listener,
            self.dashboard.listener,
            self.rtde.listener,
        ):
            listener.close()
        with contextlib.suppress(Exception):
            self.laser.close()
        self._stop.set()
        self._tick.join(2.0)
        self.frames.close()
        self.verifier.stop()
        self.cell.close()


def _contract_names(target: dict[str, Any] | None) -> dict[str, Any] | None:
    """The target's pose with its kind as the control channel names it (`two-sided`)."""
    if target is None:
        return None
    kind = next((k for k, scene in SCENE_TARGETS.items() if scene == target["kind"]), None)
    return {**target, "kind": kind or target["kind"]}
