"""Arm motion on request: one joint or Cartesian move, with the planned and the executed joint
paths logged side by side (the service's `move` command).

The driver checks its joint limits, speed limits and workspace box itself; this layer refuses
nothing but a safety stop or a cancel, and records what was asked and what happened.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Sequence

import numpy as np

from drivers.base import Arm, pose_matrix
from omnisort_hw.core.motion import MotionLimits as PlanLimits
from omnisort_hw.core.motion import plan_joint_move
from omnisort_hw.pipeline.replies import MoveReply
from omnisort_hw.pipeline.requests import MoveRequest
from omnisort_hw.pipeline.rig import raise_if_cancelled
from omnisort_hw.runlog import RunLog

_log = logging.getLogger(__name__)


class ArmMover:
    """Moves an arm and logs each move on the `motion_ms` timeline (one segment per move)."""

    def __init__(self) -> None:
        self._motion_count = 0

    def move(
        self, arm: Arm, rl: RunLog, request: MoveRequest, cancel: threading.Event | None = None
    ) -> MoveReply:
        """Move to the request's `joints_deg` (joint space), or to its `matrix` / `pose` ([x, y,
        z mm, rotation vector deg]) along a straight TCP line; returns the joints and TCP pose
        reached."""
        joints_deg, pose, matrix = request.joints_deg, request.pose, request.matrix
        speed_deg_s, speed_mm_s = request.speed_deg_s, request.speed_mm_s
        arm.safety_status().raise_if_stopped(arm.name)
        raise_if_cancelled(cancel)
        start = np.asarray(arm.joint_positions(), float)
        sampler = _JointSampler(arm)
        if joints_deg is not None:
            target = np.asarray(joints_deg, float)
            rl.event("arm/command", f"move_joints to {np.round(target, 3).tolist()} deg")
            try:
                self._log_planned_joint_move(rl, start, target, speed_deg_s)
            except Exception as exc:
                _log.warning("could not log the planned trajectory: %s", exc)
            raise_if_cancelled(cancel)
            with sampler:
                arm.move_joints(target, speed_deg_s=speed_deg_s)
        else:
            T = np.asarray(matrix, float) if matrix is not None else None
            if T is None:
                p = np.asarray(pose, float)
                T = pose_matrix(p[:3], p[3:])
            rl.event("arm/command", f"move_linear to xyz {np.round(T[:3, 3], 2).tolist()} mm")
            rl.pose("arm/planned/tcp", T)
            raise_if_cancelled(cancel)
            with sampler:
                arm.move_linear(T, speed_mm_s=speed_mm_s)
        end = np.asarray(arm.joint_positions(), float)
        tcp = np.asarray(arm.tcp_pose(), float)
        self._log_joint_series(rl, "arm/executed", sampler.times, sampler.samples)
        rl.pose("arm/executed/tcp", tcp)
        return MoveReply(np.round(end, 4).tolist(), np.round(tcp, 4).tolist())

    def _log_planned_joint_move(
        self, rl: RunLog, start: np.ndarray, target: np.ndarray, speed_deg_s: float | None
    ) -> None:
        """Log the joint trajectory the core's planner expects for this move (for review)."""
        limits = PlanLimits(joint_speed_deg_s=speed_deg_s) if speed_deg_s else PlanLimits()
        traj = plan_joint_move(start, target, limits)
        self._log_joint_series(rl, "arm/planned", traj.t, traj.q)

    def _log_joint_series(
        self,
        rl: RunLog,
        prefix: str,
        t: Sequence[float] | np.ndarray,
        q: Sequence[np.ndarray] | np.ndarray,
    ) -> None:
        """Joint angles as scalars `PREFIX/q1..q6` on the `motion_ms` timeline, which counts
        milliseconds since the move began plus 10^6 times the move's number (one segment per
        move, planned and executed side by side)."""
        if not rl.enabled or len(t) == 0:
            return
        q = np.asarray(q, float).reshape(-1, 6)
        base = self._motion_count * 1_000_000
        for ti, qi in zip(t, q, strict=True):
            rl.set_step("motion_ms", base + round(float(ti) * 1000))
            for j in range(6):
                rl.scalar(f"{prefix}/q{j + 1}", float(qi[j]))
        if prefix.endswith("executed"):
            self._motion_count += 1


class _JointSampler:
    """Samples the arm's joint positions every `period_s` while a motion runs (executed path)."""

    def __init__(self, arm: Arm, period_s: float = 0.05) -> None:
        self.arm = arm
        self.period_s = period_s
        self.times: list[float] = []
        self.samples: list[np.ndarray] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="joint-sampler", daemon=True)
        self._t0 = 0.0

    def _run(self) -> None:
        while True:
            try:
                q = np.asarray(self.arm.joint_positions(), float)
            except Exception:
                q = None
            if q is not None and q.shape == (6,):
                self.times.append(time.monotonic() - self._t0)
                self.samples.append(q)
            if self._stop.wait(self.period_s):
                return

    def __enter__(self) -> _JointSampler:
        self._t0 = time.monotonic()
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        try:
            q = np.asarray(self.arm.joint_positions(), float)
            self.times.append(time.monotonic() - self._t0)
            self.samples.append(q)
        except Exception:
            return
