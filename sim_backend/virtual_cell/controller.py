"""The emulated UR controller: robot and safety state, registers, I/O, motion, control script.

`URController` is what the protocol servers (`servers.py`) read and write. A 500 Hz tick
(`tick()`, driven by `VirtualCell`) advances the running motion in real time, runs the state
machine of ur-rtde's control script natively (no URScript interpreter: the script uploaded on
the script port is recognised and its register handshake is carried out here), drives the
simulated gripper from the configured digital output, steps the physics and publishes one
snapshot of every RTDE output field.

Units are the controller's: radians, metres, rotation vectors. Moves are planned by the core
(`omnisort_hw.core.motion`) at the controller's 500 Hz and played back against the wall clock.
A path (ur-rtde's `moveJ(path)`, `moveL(path)`, `movePath`: the control script re-uploaded with
the path's `movej`/`movel` lines injected, then command 45) is planned by the core's blended
path (`omnisort_hw.core.blended_path`), the same model the simulated arm plays. UR's own
trapezoidal timing, blend shapes and speed scaling are not modelled (see docs/virtual_cell.md).

Over 600 lines: one state machine under one lock (robot and safety state, the control
script's handshake, motion playback, I/O); its parts change state together at each tick.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from omnisort_hw.core.blended_path import Segment, plan_blended_path, resample
from omnisort_hw.core.frames import pose_from_xyz_rotvec, xyz_rotvec_from_pose
from omnisort_hw.core.kinematics import forward, nearest_solution
from omnisort_hw.core.motion import MotionLimits, plan_joint_move, plan_linear_move
from omnisort_hw.errors import MotionRefusedError

log = logging.getLogger("virtual_cell.controller")

RATE_HZ = 500.0
VERSION = (5, 15, 0, 11946)  # PolyScope 5.15 (e-Series): ur-rtde then uses 500 Hz and 5.x paths

# robot_mode, safety_mode and runtime_state numbers of the RTDE guide.
POWER_OFF, IDLE, RUNNING = 3, 5, 7
NORMAL, PROTECTIVE_STOP, ROBOT_EMERGENCY_STOP = 1, 3, 7
STOPPED, PLAYING = 1, 2
ROBOT_MODE_NAMES = {POWER_OFF: "POWER_OFF", IDLE: "IDLE", RUNNING: "RUNNING"}
SAFETY_MODE_NAMES = {
    NORMAL: "NORMAL",
    PROTECTIVE_STOP: "PROTECTIVE_STOP",
    ROBOT_EMERGENCY_STOP: "ROBOT_EMERGENCY_STOP",
}

# ur-rtde's RobotCommand numbers the native script machine carries out.
MOVEJ, MOVEJ_IK, MOVEL, MOVEL_FK = 1, 2, 3, 4
MOVE_PATH = 45
SET_PAYLOAD, SET_TCP, PROTECTIVE_STOP_CMD = 17, 29, 31
STOPL, STOPJ, SET_WATCHDOG = 33, 34, 35
GET_TCP_OFFSET, FK_DEFAULT, IS_STEADY = 40, 43, 47
SPEED_STOP, SERVO_STOP = 15, 16
STOP_SCRIPT = 255
# Commands the script answers without waiting for the clear (its "realtime" branch).
REALTIME = {24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}
STOP_DECEL_RAD_S2 = 10.0  # how hard a protective or emergency stop brakes (category 2-like)

CONTROL_SCRIPT_MARKER = "RTDE Control Script"
_OFFSET_RE = re.compile(r"# int register offset\n\s*(\d+)")
# A waypoint line ur-rtde's Path::toScriptCode injects: movej([q],a=,v=,r=) / movel(p[x],...).
_PATH_RE = re.compile(
    r"^\s*(movej|movel)\((p?)\[([^\]]*)\],a=([^,]+),v=([^,]+),r=([^)]+)\)\s*$", re.M
)
# The joints' speed and acceleration a movel may use (deg/s, deg/s^2; the hardware's).
MOVEL_JOINT_CAPS = (180.0, 800.0)


@dataclass(frozen=True)
class PathRow:
    """One injected path waypoint: movej or movel, pose (p[...]) or joints, UR units."""

    move: str
    is_pose: bool
    values: np.ndarray
    accel: float
    speed: float
    blend_m: float


def parse_path(text: str) -> list[PathRow]:
    """The path waypoints injected into the control script (empty when there are none)."""
    return [
        PathRow(
            move,
            p == "p",
            np.array([float(v) for v in vals.split(",")]),
            float(a),
            float(v),
            float(r),
        )
        for move, p, vals, a, v, r in _PATH_RE.findall(text)
    ]


@dataclass
class _Motion:
    """A move being played back: joint samples (rad) at RATE_HZ from `t0`."""

    q: np.ndarray
    t0: float
    is_async: bool
    what: str

    def sample(self, now: float) -> tuple[np.ndarray, np.ndarray, bool]:
        """(q, qd, finished) at time `now`."""
        k = int((now - self.t0) * RATE_HZ)
        last = len(self.q) - 1
        if k >= last:
            return self.q[last], np.zeros(6), True
        k = max(k, 0)
        return self.q[k], (self.q[k + 1] - self.q[k]) * RATE_HZ, False


@dataclass
class _Outputs:
    """Digital outputs as bit fields (standard 0-7, configurable 0-7, tool 0-1)."""

    standard: int = 0
    configurable: int = 0
    tool: int = 0

    @property
    def bits(self) -> int:
        return self.standard | (self.configurable << 8) | (self.tool << 16)


@dataclass
class ControllerEvents:
    """What happened, for the control channel and the log (commands seen, scripts run)."""

    commands: list[int] = field(default_factory=list)
    scripts: int = 0
    refused_scripts: int = 0
    motions: int = 0
    last_motion_s: float = 0.0  # the planned duration of the last motion started


def _decel(q0: np.ndarray, qd0: np.ndarray, decel: float) -> np.ndarray:
    """Joint samples (rad) braking every joint from qd0 to rest together at `decel` (rad/s^2)
    on the leading joint."""
    peak = float(np.max(np.abs(qd0)))
    if peak < 1e-9 or decel <= 0:
        return q0[None].copy()
    T = peak / decel
    t = np.arange(0.0, T + 1.0 / RATE_HZ, 1.0 / RATE_HZ)
    t = np.minimum(t, T)
    return q0 + qd0 * t[:, None] - 0.5 * (qd0 / T) * (t[:, None] ** 2)


class URController:
    """One emulated UR controller over a simulated arm (`sim_backend.devices.SimArm`).

    `gripper_output` names the digital output ("tool", 0) whose level drives the simulated
    gripper (True = closed). `unlock_delay_s` is how long after a protective stop the
    dashboard refuses to unlock it (5 s on a real controller).
    """

    def __init__(
        self,
        arm: Any,
        gripper_output: tuple[str, int] = ("tool", 0),
        unlock_delay_s: float = 5.0,
        serial_number: str = "20235500001",
    ) -> None:
        self.arm = arm
        self.cell = arm.cell
        self.world = self.cell.world
        self.model = arm.model
        self.lock = threading.RLock()
        self.t_start = time.monotonic()
        self.gripper_output = gripper_output
        self.unlock_delay_s = float(unlock_delay_s)
        self.serial_number = serial_number
        self.version = VERSION
        offset = arm.robot.gripper.tcp_offset_mm / 1000.0
        self.tcp = np.array([0.0, 0.0, offset, 0.0, 0.0, 0.0])
        self.q = np.deg2rad(self.world.joints())
        self.qd = np.zeros(6)
        self.robot_mode = RUNNING
        self.safety_mode = NORMAL
        self.runtime_state = STOPPED
        self.loaded_program = ""
        self.stopped_at = 0.0
        self.in_int = [0] * 48
        self.in_double = [0.0] * 48
        self.out_int = [0] * 48
        self.out_double = [0.0] * 48
        self.outputs = _Outputs()
        self.speed_slider = 1.0
        self.events = ControllerEvents()
        self._motion: _Motion | None = None
        self._path: list[PathRow] = []
        self._stale_cmd = 0
        self._script = False
        self._executing = False
        self._sync_wait = False
        self._reg = 0
        self._async_count = 0
        self._async_id = 0
        self._gripper_level = False
        self._phys_due = 0.0
        self._q_prev_deg = np.rad2deg(self.q)
        self._last_tick = time.monotonic()
        self.snapshot: dict[str, Any] = {}
        self.publish(self._last_tick)

    # ---- state read by the servers --------------------------------------------------------

    def tool_matrix(self) -> np.ndarray:
        """The installation TCP (flange -> TCP) as a 4x4 in mm."""
        return _pose_matrix(self.tcp)

    def tcp_pose(self, q: np.ndarray | None = None) -> list[float]:
        """TCP pose [m, rotvec rad] in the base frame for joints q (rad; default: actual)."""
        q = self.q if q is None else q
        T = forward(self.model, np.rad2deg(q), self.tool_matrix())
        xyz_mm, rotvec_deg = xyz_rotvec_from_pose(T)
        return [*(xyz_mm / 1000.0), *np.deg2rad(rotvec_deg)]

    def publish(self, now: float) -> None:
        """Build the snapshot of every RTDE output field (read lock-free by the senders)."""
        q = [float(v) for v in self.q]
        qd = [float(v) for v in self.qd]
        pose = self.tcp_pose()
        safety_bits = {
            NORMAL: 1 << 0,
            PROTECTIVE_STOP: (1 << 2) | (1 << 10),
            ROBOT_EMERGENCY_STOP: (1 << 6) | (1 << 7) | (1 << 10),
        }[self.safety_mode]
        powered = self.robot_mode in (IDLE, RUNNING)
        status_bits = int(powered) | (int(self.runtime_state == PLAYING) << 1)
        snap: dict[str, Any] = {
            "timestamp": now - self.t_start,
            "target_q": q,
            "actual_q": q,
            "target_qd": qd,
            "actual_qd": qd,
            "actual_TCP_pose": pose,
            "target_TCP_pose": pose,
            "robot_mode": self.robot_mode,
            "joint_mode": [253 if self.robot_mode == RUNNING else 239] * 6,
            "safety_mode": self.safety_mode,
            "safety_status": self.safety_mode,
            "runtime_state": self.runtime_state,
            "robot_status_bits": status_bits,
            "safety_status_bits": safety_bits,
            "actual_digital_output_bits": self.outputs.bits,
            "actual_digital_input_bits": 0,
            "speed_scaling": 1.0 if self.robot_mode == RUNNING else 0.0,
            "target_speed_fraction": self.speed_slider,
            "actual_main_voltage": 48.0,
            "actual_robot_voltage": 48.0 if powered else 0.0,
            "joint_temperatures": [30.0] * 6,
            "actual_execution_time": 0.3,
        }
        for i, v in enumerate(self.out_int):
            snap[f"output_int_register_{i}"] = v
        for i, x in enumerate(self.out_double):
            snap[f"output_double_register_{i}"] = x
        self.snapshot = snap

    def value(self, name: str, kind: str, snap: dict[str, Any]) -> Any:
        """The value of output field `name` of RTDE type `kind` (zeros for unmodelled ones)."""
        v = snap.get(name)
        if v is not None:
            return v
        return {"VECTOR3D": [0.0] * 3, "VECTOR6D": [0.0] * 6, "VECTOR6INT32": [0] * 6}.get(
            kind, [0] * 6 if kind == "VECTOR6UINT32" else (0.0 if kind == "DOUBLE" else 0)
        )

    # ---- inputs written by RTDE clients ----------------------------------------------------

    def write_inputs(self, fields: dict[str, Any]) -> None:
        """Apply one input data package (registers, masked digital outputs, speed slider)."""
        with self.lock:
            for name, value in fields.items():
                if name.startswith("input_int_register_"):
                    self.in_int[int(name.rsplit("_", 1)[1])] = int(value)
                elif name.startswith("input_double_register_"):
                    self.in_double[int(name.rsplit("_", 1)[1])] = float(value)
            for kind in ("standard", "configurable", "tool"):
                group = "tool" if kind == "tool" else kind
                mask = fields.get(f"{group}_digital_output_mask")
                if mask is None:
                    continue
                level = int(fields.get(f"{group}_digital_output", 0))
                old = getattr(self.outputs, kind)
                width = 0x3 if kind == "tool" else 0xFF
                setattr(self.outputs, kind, ((old & ~mask) | (level & mask)) & width)
            if int(fields.get("speed_slider_mask", 0)) == 1:
                self.speed_slider = float(np.clip(fields.get("speed_slider_fraction", 1.0), 0, 1))

    # ---- the script port -------------------------------------------------------------------

    def run_script(self, text: str) -> bool:
        """A program arrived on the script port. ur-rtde's control script starts the native
        state machine; anything else is logged and ignored (no URScript interpreter)."""
        with self.lock:
            if CONTROL_SCRIPT_MARKER not in text:
                log.warning(
                    "script port: a program that is not ur-rtde's control script was "
                    "ignored (the virtual cell does not interpret URScript)"
                )
                return False
            if self.robot_mode != RUNNING or self.safety_mode != NORMAL:
                self.events.refused_scripts += 1
                log.warning(
                    "script refused: robot mode %s, safety %s",
                    ROBOT_MODE_NAMES.get(self.robot_mode),
                    self.safety_mode,
                )
                return False
            self._halt_motion(STOP_DECEL_RAD_S2)
            found = _OFFSET_RE.search(text)
            self._reg = int(found.group(1)) if found else 0
            self._path = parse_path(text)
            # A command left in the register by the previous program (ur-rtde's stop before a
            # re-upload) is not acted on: a real script starts too slowly to see it.
            self._stale_cmd = self.in_int[self._reg]
            self._script = True
            self._executing = False
            self._sync_wait = False
            self.loaded_program = "<ur-rtde control script>"
            self.runtime_state = PLAYING
            self.events.scripts += 1
            self._write_async(-1)
            self.out_int[self._reg] = 1
            log.info("ur-rtde control script running (register offset %d)", self._reg)
            return True

    def stop_program(self, why: str) -> None:
        """The running program ends (dashboard stop, stop script, a stop, a script error)."""
        with self.lock:
            if self._motion is not None and self._motion.is_async:
                self._write_async(-1)
            self._halt_motion(STOP_DECEL_RAD_S2)
            if self._script:
                log.info("control script stopped: %s", why)
            self._script = False
            self._sync_wait = False
            self.runtime_state = STOPPED

    # ---- safety (control channel and dashboard) --------------------------------------------

    def protective_stop(self) -> None:
        with self.lock:
            if self.safety_mode == NORMAL:
                self.safety_mode = PROTECTIVE_STOP
                self.stopped_at = time.monotonic()
                self.stop_program("protective stop")

    def emergency_stop(self) -> None:
        with self.lock:
            self.safety_mode = ROBOT_EMERGENCY_STOP
            self.stop_program("emergency stop")
            self.robot_mode = POWER_OFF

    def release_emergency_stop(self) -> None:
        """The e-stop button is released: safety normal, the arm stays powered off."""
        with self.lock:
            if self.safety_mode == ROBOT_EMERGENCY_STOP:
                self.safety_mode = NORMAL

    def unlock_protective_stop(self) -> str:
        with self.lock:
            if self.safety_mode != PROTECTIVE_STOP:
                return "Protective stop releasing"
            if time.monotonic() - self.stopped_at < self.unlock_delay_s:
                return (
                    f"Cannot unlock protective stop until {self.unlock_delay_s:g}s after "
                    "occurrence. Always inspect cause of protective stop before unlocking"
                )
            self.safety_mode = NORMAL
            return "Protective stop releasing"

    def power(self, on: bool) -> None:
        with self.lock:
            if not on:
                self.stop_program("power off")
                self.robot_mode = POWER_OFF
            elif self.robot_mode == POWER_OFF and self.safety_mode == NORMAL:
                self.robot_mode = IDLE

    def brake_release(self) -> None:
        with self.lock:
            if self.robot_mode in (POWER_OFF, IDLE) and self.safety_mode == NORMAL:
                self.robot_mode = RUNNING

    # ---- the 500 Hz tick -------------------------------------------------------------------

    def tick(self) -> None:
        """Advance motion, the script machine, the gripper and the physics; publish."""
        now = time.monotonic()
        with self.lock:
            self._advance(now)
            if self._script:
                self._script_step(now)
            self._drive_gripper()
            q_deg = np.rad2deg(self.q)
        with self.cell.lock:
            # Physics at its own 240 Hz, the arm moved through the joints in between (a held
            # cube follows a path, not a jump, however late this tick is).
            self._phys_due += (now - self._last_tick) / self.world.time_step
            steps = min(int(self._phys_due), 24)
            self._phys_due = min(self._phys_due - steps, 1.0)
            q_prev = self._q_prev_deg
            for i in range(1, steps + 1):
                self.world.set_joints(q_prev + (q_deg - q_prev) * (i / steps))
                self.world.step(1)
            if not steps:
                self.world.set_joints(q_deg)
            self._q_prev_deg = q_deg
        self._last_tick = now
        with self.lock:
            self.publish(now)

    def _advance(self, now: float) -> None:
        m = self._motion
        if m is None:
            self.qd = np.zeros(6)
            return
        q, qd, done = m.sample(now)
        self.q, self.qd = q.copy(), qd
        if done:
            self._motion = None
            if m.is_async:
                self._write_async(-1)

    def _script_step(self, now: float) -> None:
        reg = self._reg
        if self._sync_wait:
            if self._motion is None:
                self._sync_wait = False
                self.out_int[reg] = 2
            return
        cmd = self.in_int[reg]
        if cmd != self._stale_cmd:
            self._stale_cmd = 0
        elif cmd:
            return
        if cmd in REALTIME:
            self._process(cmd)
            self.out_int[reg] = 1
        elif cmd == 0:
            self._executing = False
            self.out_int[reg] = 1
        elif not self._executing:
            self._executing = True
            self.events.commands.append(cmd)
            del self.events.commands[:-200]
            keep = self._process(cmd)
            if not keep:
                return
            if not self._sync_wait:
                self.out_int[reg] = 2

    def _process(self, cmd: int) -> bool:
        """Carry out one command of the control script; False when the script ended."""
        reg = self._reg
        d = self.in_double[reg : reg + 24]
        is_async = self.in_int[reg + 1] == 1
        try:
            if cmd in (MOVEJ, MOVEJ_IK, MOVEL, MOVEL_FK):
                self._start_move(cmd, np.asarray(d[:6], float), d[6], d[7], is_async)
            elif cmd == MOVE_PATH:
                self._start_path(is_async)
            elif cmd in (STOPJ, STOPL, SPEED_STOP, SERVO_STOP):
                self._stop_async_move()
                decel = d[0] if cmd in (STOPJ, STOPL) else 10.0
                if cmd == STOPL:  # a tool deceleration (m/s^2): brake the joints comparably
                    decel = decel / 0.5
                self._halt_motion(max(decel, 0.1))
                if cmd in (STOPJ, STOPL) and not is_async:
                    self._sync_wait = self._motion is not None
            elif cmd == SET_TCP:
                self.tcp = np.asarray(d[:6], float)
            elif cmd == GET_TCP_OFFSET:
                self.out_double[reg : reg + 6] = [float(v) for v in self.tcp]
            elif cmd == FK_DEFAULT:
                self.out_double[reg : reg + 6] = self.tcp_pose()
            elif cmd == IS_STEADY:
                self.out_int[reg + 1] = int(self._motion is None)
            elif cmd == PROTECTIVE_STOP_CMD:
                self.protective_stop()
                return False
            elif cmd == STOP_SCRIPT:
                self.stop_program("stop script command")
                return False
            elif cmd not in (SET_PAYLOAD, SET_WATCHDOG):
                log.warning("control script command %d is not modelled; acknowledged only", cmd)
        except (MotionRefusedError, ValueError) as exc:
            log.error("control script error, program stopped: %s", exc)
            self.stop_program(f"script error: {exc}")
            return False
        return True

    def _start_move(
        self, cmd: int, target: np.ndarray, speed: float, accel: float, is_async: bool
    ) -> None:
        self._stop_async_move()
        self._halt_motion(STOP_DECEL_RAD_S2)
        q0 = np.rad2deg(self.q)
        tool = self.tool_matrix()
        if cmd in (MOVEJ, MOVEJ_IK):
            if cmd == MOVEJ_IK:
                q1 = nearest_solution(self.model, _pose_matrix(target), q0, tool=tool)
            else:
                q1 = np.rad2deg(target)
            limits = MotionLimits(
                joint_speed_deg_s=float(np.rad2deg(speed)),
                joint_acc_deg_s2=float(np.rad2deg(accel)),
                rate_hz=RATE_HZ,
            )
            traj = plan_joint_move(q0, np.asarray(q1, float), limits, model=self.model)
        else:
            T = (
                _pose_matrix(target)
                if cmd == MOVEL
                else forward(self.model, np.rad2deg(target), tool)
            )
            limits = replace(_movel_limits(speed, accel), rate_hz=RATE_HZ)
            traj = plan_linear_move(self.model, q0, T, limits, tool=tool)
        q = np.deg2rad(traj.q)
        if cmd == MOVEJ:
            q[-1] = target
        self._play(q, is_async, "movej" if cmd < 3 else "movel")

    def pendant_move(
        self, q_deg: np.ndarray | None = None, xyz_mm: np.ndarray | None = None
    ) -> dict[str, Any]:
        """A joint move started from the pendant (the simulator's panel), to joints `q_deg` or
        with the tool kept as it is to the base-frame point `xyz_mm` through the core's
        inverse kinematics; at a pendant's jog speed (30 deg/s, 60 deg/s^2). Refused while the
        arm moves, a script command runs or a stop holds it (MotionRefusedError)."""
        with self.lock:
            if self.safety_mode != NORMAL or self.robot_mode != RUNNING:
                raise MotionRefusedError(
                    f"the arm is not ready ({SAFETY_MODE_NAMES.get(self.safety_mode)},"
                    f" {ROBOT_MODE_NAMES.get(self.robot_mode)})"
                )
            if self._motion is not None or self._executing:
                raise MotionRefusedError("the arm is moving: wait for it to stop")
            q0 = np.rad2deg(self.q)
            tool = self.tool_matrix()
            if xyz_mm is not None:
                T = forward(self.model, q0, tool)
                T[:3, 3] = np.asarray(xyz_mm, float)
                q1 = nearest_solution(self.model, T, q0, tool=tool)
            else:
                q1 = np.asarray(q_deg, float)
            limits = MotionLimits(joint_speed_deg_s=30.0, joint_acc_deg_s2=60.0, rate_hz=RATE_HZ)
            traj = plan_joint_move(q0, q1, limits, model=self.model)
            self._motion = _Motion(np.deg2rad(traj.q), time.monotonic(), False, "pendant")
            self.events.motions += 1
            self.events.last_motion_s = (len(traj.q) - 1) / RATE_HZ
            return {"q_deg": [float(v) for v in q1], "seconds": self.events.last_motion_s}

    def _start_path(self, is_async: bool) -> None:
        """Play the injected path as one blended motion (exec_move_path of the script)."""
        self._stop_async_move()
        self._halt_motion(STOP_DECEL_RAD_S2)
        if not self._path:
            log.warning("move_path without an injected path: nothing to do")
            return
        q_prev = np.rad2deg(self.q)
        tool = self.tool_matrix()
        segments = []
        for row in self._path:
            if row.move == "movej":
                q1 = (
                    nearest_solution(self.model, _pose_matrix(row.values), q_prev, tool=tool)
                    if row.is_pose
                    else np.rad2deg(row.values)
                )
                lim = MotionLimits(
                    joint_speed_deg_s=float(np.rad2deg(row.speed)),
                    joint_acc_deg_s2=float(np.rad2deg(row.accel)),
                )
                segments.append(Segment("joint", np.asarray(q1, float), lim, row.blend_m * 1e3))
                q_prev = np.asarray(q1, float)
            else:
                T = (
                    _pose_matrix(row.values)
                    if row.is_pose
                    else forward(self.model, np.rad2deg(row.values), tool)
                )
                lim = _movel_limits(row.speed, row.accel)
                segments.append(Segment("linear", T, lim, row.blend_m * 1e3))
        path = plan_blended_path(self.model, np.rad2deg(self.q), segments, tool=tool)
        q = np.deg2rad(resample(path.trajectory, RATE_HZ).q)
        self._play(q, is_async, "move_path")

    def _play(self, q: np.ndarray, is_async: bool, what: str) -> None:
        self._motion = _Motion(q, time.monotonic(), is_async, what)
        self.events.motions += 1
        self.events.last_motion_s = (len(q) - 1) / RATE_HZ
        if is_async:
            self._write_async(0)
        else:
            self._sync_wait = True

    def _stop_async_move(self) -> None:
        if self._motion is not None and self._motion.is_async:
            self._motion.is_async = False
            self._write_async(-1)

    def _halt_motion(self, decel: float) -> None:
        """Replace the running move by braking to rest from the current velocity."""
        if self._motion is None:
            return
        q = _decel(self.q, self.qd, decel)
        self._motion = _Motion(q, time.monotonic(), False, "stop") if len(q) > 1 else None
        if self._motion is None:
            self.qd = np.zeros(6)

    def _write_async(self, value: int) -> None:
        """ur-rtde's async progress register (output int 2): op id, write count, running bit."""
        self._async_count = (self._async_count + 1) % 128
        if value == 0:
            self._async_id = (self._async_id + 1) % 128
        reg = self._async_count * 65536 + self._async_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self.out_int[self._reg + 2] = reg

    def _drive_gripper(self) -> None:
        kind, pin = self.gripper_output
        level = bool((getattr(self.outputs, kind) >> pin) & 1)
        if level == self._gripper_level:
            return
        self._gripper_level = level
        gripper = self.arm.gripper
        if level:
            gripper.close()
        else:
            gripper.open()

    @property
    def moving(self) -> bool:
        return self._motion is not None


def _movel_limits(speed: float, accel: float) -> MotionLimits:
    """A movel's limits: the tool's speed and acceleration (m/s, m/s^2), the joints' maxima."""
    return MotionLimits(
        joint_speed_deg_s=MOVEL_JOINT_CAPS[0],
        joint_acc_deg_s2=MOVEL_JOINT_CAPS[1],
        linear_speed_mm_s=float(speed * 1000.0),
        linear_acc_mm_s2=float(accel * 1000.0),
        angular_speed_deg_s=180.0,
        angular_acc_deg_s2=720.0,
    )


def _pose_matrix(pose: np.ndarray) -> np.ndarray:
    """4x4 (mm) from a UR pose [m, rotvec rad]."""
    pose = np.asarray(pose, float)
    return pose_from_xyz_rotvec(pose[:3] * 1000.0, np.rad2deg(pose[3:6]))
