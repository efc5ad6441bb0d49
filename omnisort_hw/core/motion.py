"""Motion planning for the UR arm: timed joint and straight-line moves (collision checks of
the planned moves: `collision`).

Everything is in the UR base frame B, millimetres, degrees and seconds. Trajectories are
sampled at a fixed rate and start and end exactly at their targets. A joint move follows a
straight line in joint space with a synchronised trapezoidal speed profile; a linear move
keeps the tool on a straight line (slerp of the orientation) with per-sample analytic
inverse kinematics that stays on one branch, refusing joint jumps, singularities and joint
limits, and is timed so that the Cartesian and the joint speed and acceleration limits all
hold.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from omnisort_hw.core.kinematics import (
    JointLimitError,
    SingularPoseError,
    UnreachableError,
    URModel,
    forward,
    inverse,
    nearest_solution,
    wrap_deg,
)
from omnisort_hw.errors import MotionRefusedError

__all__ = [
    "MotionLimits",
    "Trajectory",
    "concatenate",
    "offset_pose",
    "plan_approach",
    "plan_joint_move",
    "plan_linear_move",
    "plan_retreat",
]

_MAX_PATH_SAMPLES = 200_000
# Joint derivatives along a linear path are estimated on the path grid; planning against
# 99 % of the joint limits absorbs the estimate's error (< 0.01 % at the default grid).
_GRID_HEADROOM = 0.99

# ---------------------------------------------------------------------------------------------
# Records


@dataclass(frozen=True)
class MotionLimits:
    """Speed and acceleration limits of a move, and the sampling rate of its trajectory.

    Joint limits are one value for all joints or six values (deg/s, deg/s^2). The defaults
    are UR's movej / movel defaults (1.05 rad/s, 1.4 rad/s^2; 0.25 m/s, 1.2 m/s^2).
    """

    joint_speed_deg_s: float | tuple[float, ...] = 60.0
    joint_acc_deg_s2: float | tuple[float, ...] = 80.0
    linear_speed_mm_s: float = 250.0
    linear_acc_mm_s2: float = 1200.0
    angular_speed_deg_s: float = 60.0
    angular_acc_deg_s2: float = 80.0
    rate_hz: float = 125.0

    def __post_init__(self) -> None:
        for name in (
            "linear_speed_mm_s",
            "linear_acc_mm_s2",
            "angular_speed_deg_s",
            "angular_acc_deg_s2",
            "rate_hz",
        ):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"MotionLimits.{name} must be positive")
        for arr, name in (
            (self.joint_speed, "joint_speed_deg_s"),
            (self.joint_acc, "joint_acc_deg_s2"),
        ):
            if not np.all(arr > 0.0):
                raise ValueError(f"MotionLimits.{name} must be positive (one or six values)")

    @property
    def joint_speed(self) -> np.ndarray:
        """Joint speed limits (6,) deg/s."""
        return np.broadcast_to(np.asarray(self.joint_speed_deg_s, dtype=float), (6,)).copy()

    @property
    def joint_acc(self) -> np.ndarray:
        """Joint acceleration limits (6,) deg/s^2."""
        return np.broadcast_to(np.asarray(self.joint_acc_deg_s2, dtype=float), (6,)).copy()


@dataclass(frozen=True)
class Trajectory:
    """Timed joint positions: t (M,) s from 0, q (M, 6) deg, sampled at a fixed rate.

    kind: "joint", "linear" or "sequence" (several moves concatenated).
    """

    t: np.ndarray
    q: np.ndarray
    kind: str

    @property
    def duration(self) -> float:
        """Time of the last sample, s."""
        return float(self.t[-1])

    def __len__(self) -> int:
        return int(self.t.shape[0])


def concatenate(trajectories: Sequence[Trajectory]) -> Trajectory:
    """One trajectory from consecutive moves; each must start where the previous one ended."""
    if not trajectories:
        raise ValueError("concatenate needs at least one trajectory")
    ts, qs = [trajectories[0].t], [trajectories[0].q]
    offset = trajectories[0].duration
    for prev, nxt in itertools.pairwise(trajectories):
        if not np.allclose(prev.q[-1], nxt.q[0], atol=1e-6):
            raise ValueError("trajectories do not join: a move starts away from the previous end")
        ts.append(nxt.t[1:] + offset)
        qs.append(nxt.q[1:])
        offset += nxt.duration
    return Trajectory(t=np.concatenate(ts), q=np.concatenate(qs), kind="sequence")


# ---------------------------------------------------------------------------------------------
# Time parametrisation


def _trapezoid(v_max: float, a_max: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Times (M,) and path parameter s (M,) from 0 to 1 with |s'| <= v_max, |s''| <= a_max.

    The profile's duration is stretched to a whole number of sample periods, which only
    lowers speed and acceleration, so every sample is one period apart and the last one
    is exactly at s = 1.
    """
    if v_max * v_max >= a_max:  # no cruise phase: triangle
        t_acc = np.sqrt(1.0 / a_max)
        v_peak, t_cruise = a_max * t_acc, 0.0
    else:
        t_acc = v_max / a_max
        v_peak, t_cruise = v_max, (1.0 - v_max * t_acc) / v_max
    duration = 2.0 * t_acc + t_cruise
    n = max(1, int(np.ceil(duration * rate_hz - 1e-9)))
    k = n / (rate_hz * duration)  # time stretch >= 1
    t = np.arange(n + 1) / rate_hz
    tau = t / k  # time on the unstretched profile
    s_acc = 0.5 * a_max * t_acc * t_acc
    s = np.where(
        tau < t_acc,
        0.5 * a_max * tau * tau,
        np.where(
            tau <= t_acc + t_cruise,
            s_acc + v_peak * (tau - t_acc),
            1.0 - 0.5 * a_max * np.maximum(duration - tau, 0.0) ** 2,
        ),
    )
    s[-1] = 1.0
    return t, np.clip(s, 0.0, 1.0)


def _speed_caps(limits: MotionLimits, model: URModel | None) -> tuple[np.ndarray, np.ndarray]:
    """Joint speed (capped at the model's hardware maximum) and acceleration limits (6,)."""
    v = limits.joint_speed
    if model is not None:
        v = np.minimum(v, np.asarray(model.max_speed_deg_s, dtype=float))
    return v, limits.joint_acc


def _check_within_limits(model: URModel, q: np.ndarray, what: str, lim: np.ndarray) -> None:
    """Raise JointLimitError naming the joint if any row of q (M, 6) leaves lim (6, 2)."""
    bad = (q < lim[:, 0] - 1e-9) | (q > lim[:, 1] + 1e-9)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise JointLimitError(
            f"{what}: joint {j + 1} of the {model.name} would reach {q[i, j]:.2f} deg, outside "
            f"its limits [{lim[j, 0]:.0f}, {lim[j, 1]:.0f}] deg"
        )


def plan_joint_move(
    q0_deg: np.ndarray,
    q1_deg: np.ndarray,
    limits: MotionLimits | None = None,
    *,
    model: URModel | None = None,
) -> Trajectory:
    """Joint-space move from q0 to q1 (6,) deg, all joints starting and stopping together.

    The joints follow the straight line in joint space with one trapezoidal profile timed
    by the joint that needs longest. With `model`, the endpoints must be within its joint
    limits (the line between them then is too) and speeds are capped at its hardware maxima.
    """
    limits = limits or MotionLimits()
    q0 = np.asarray(q0_deg, dtype=float).reshape(6)
    q1 = np.asarray(q1_deg, dtype=float).reshape(6)
    if not (np.all(np.isfinite(q0)) and np.all(np.isfinite(q1))):
        raise ValueError("plan_joint_move needs finite joint vectors")
    if model is not None:
        _check_within_limits(model, np.stack([q0, q1]), "joint move", model.limits)
    v, a = _speed_caps(limits, model)
    delta = q1 - q0
    span = np.abs(delta)
    if not np.any(span > 0.0):
        return Trajectory(t=np.zeros(1), q=q0[None].copy(), kind="joint")
    moving = span > 0.0
    s_dot = float(np.min(v[moving] / span[moving]))
    s_ddot = float(np.min(a[moving] / span[moving]))
    t, s = _trapezoid(s_dot, s_ddot, limits.rate_hz)
    q = q0 + s[:, None] * delta
    q[0], q[-1] = q0, q1
    return Trajectory(t=t, q=q, kind="joint")


def _line_poses(T0: np.ndarray, T1: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Poses (M, 4, 4) at fractions s (M,) of the straight line and slerp from T0 to T1."""
    rots = Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]]))
    T = np.zeros((s.shape[0], 4, 4))
    T[:, :3, :3] = Slerp([0.0, 1.0], rots)(s).as_matrix()
    T[:, :3, 3] = T0[:3, 3] + s[:, None] * (T1[:3, 3] - T0[:3, 3])
    T[:, 3, 3] = 1.0
    T[0], T[-1] = T0, T1
    return T


def plan_linear_move(
    model: URModel,
    q0_deg: np.ndarray,
    T_target: np.ndarray,
    limits: MotionLimits | None = None,
    *,
    tool: np.ndarray | None = None,
    joint_limits_deg: np.ndarray | None = None,
    path_step_mm: float = 1.0,
    path_step_deg: float = 0.5,
    max_joint_step_deg: float = 5.0,
    singular_tol: float = 0.02,
) -> Trajectory:
    """Straight-line move of the tool (flange, or `tool` (4, 4) on it) from FK(q0) to T_target.

    The path is checked on a dense grid (steps of `path_step_mm` and `path_step_deg`): the
    arm stays on the inverse kinematics branch it starts on, no joint may change by more than
    `max_joint_step_deg` between grid points, no point may be within `singular_tol` of a
    singularity (|sin theta5|, |sin theta3| < tol, or the wrist centre within tol * reach of
    the shoulder singularity) and every joint must stay within limits (default: the model's).
    The timing keeps the linear and angular tool speed and acceleration and every joint's
    speed and acceleration within `limits`. Raises UnreachableError, SingularPoseError or
    JointLimitError naming where on the path the problem is.
    """
    limits = limits or MotionLimits()
    q0 = np.asarray(q0_deg, dtype=float).reshape(6)
    T1 = np.asarray(T_target, dtype=float)
    if T1.shape != (4, 4):
        raise ValueError(f"T_target must be one pose (4, 4), got {T1.shape}")
    lim = model.limits if joint_limits_deg is None else np.asarray(joint_limits_deg, dtype=float)
    _check_within_limits(model, q0[None], "linear move start", lim)
    T0 = forward(model, q0, tool)
    length = float(np.linalg.norm(T1[:3, 3] - T0[:3, 3]))
    angle = float(
        np.degrees(
            (Rotation.from_matrix(T0[:3, :3]).inv() * Rotation.from_matrix(T1[:3, :3])).magnitude()
        )
    )
    if length < 1e-9 and angle < 1e-9:
        return Trajectory(t=np.zeros(1), q=q0[None].copy(), kind="linear")
    n_dense = int(max(np.ceil(length / path_step_mm), np.ceil(angle / path_step_deg), 2)) + 1
    if n_dense > _MAX_PATH_SAMPLES:
        raise MotionRefusedError(
            f"linear move of {length:.0f} mm / {angle:.0f} deg needs {n_dense} path samples; "
            "split it or coarsen path_step_mm"
        )
    s_dense = np.linspace(0.0, 1.0, n_dense)
    T_dense = _line_poses(T0, T1, s_dense)
    track, branch = _track_branch(model, q0, T_dense, tool, singular_tol, max_joint_step_deg)
    _check_within_limits(model, track, "linear move", lim)

    # Path speed: Cartesian limits, then joint limits through dq/ds and d2q/ds2.
    s_dot = np.inf
    s_ddot = np.inf
    if length > 0.0:
        s_dot = min(s_dot, limits.linear_speed_mm_s / length)
        s_ddot = min(s_ddot, limits.linear_acc_mm_s2 / length)
    if angle > 0.0:
        s_dot = min(s_dot, limits.angular_speed_deg_s / angle)
        s_ddot = min(s_ddot, limits.angular_acc_deg_s2 / angle)
    v_j, a_j = _speed_caps(limits, model)
    v_j, a_j = _GRID_HEADROOM * v_j, _GRID_HEADROOM * a_j
    dq = np.gradient(track, s_dense, axis=0)
    d2q = np.gradient(dq, s_dense, axis=0)
    B = np.max(np.abs(dq), axis=0)
    A = np.max(np.abs(d2q), axis=0)
    with np.errstate(divide="ignore"):
        s_dot = min(s_dot, float(np.min(v_j / B)), float(np.min(np.sqrt(0.5 * a_j / A))))
        s_ddot = min(s_ddot, float(np.min((a_j - A * s_dot * s_dot) / B)))
    t, s = _trapezoid(s_dot, s_ddot, limits.rate_hz)

    # Exact IK at the samples, on the tracked branch, unwrapped next to the dense track.
    sols = inverse(model, _line_poses(T0, T1, s), tool=tool, q6_hint_deg=q0[5])
    q = sols.q[:, branch, :]
    if not sols.valid[:, branch].all():
        raise UnreachableError("linear move: the path leaves the workspace between grid points")
    q_ref = np.stack([np.interp(s, s_dense, track[:, j]) for j in range(6)], axis=1)
    q = q + 360.0 * np.round((q_ref - q) / 360.0)
    if np.max(np.abs(q - q_ref)) > max_joint_step_deg:
        raise SingularPoseError("linear move: the joints jump between path grid points")
    q[0] = q0
    _check_within_limits(model, q, "linear move", lim)
    return Trajectory(t=t, q=q, kind="linear")


def _track_branch(
    model: URModel,
    q0: np.ndarray,
    T_path: np.ndarray,
    tool: np.ndarray | None,
    singular_tol: float,
    max_step: float,
) -> tuple[np.ndarray, int]:
    """Joints (M, 6) along a dense path on the branch of q0, continuous (unwrapped) from q0.

    Branch indices of the analytic solution are continuous away from singularities, so the
    whole path is solved at once and the branch is followed by index.
    """
    sols = inverse(model, T_path, tool=tool, q6_hint_deg=q0[5], singular_tol=singular_tol)
    first = np.where(sols.valid[0], np.sum(wrap_deg(sols.q[0] - q0) ** 2, axis=-1), np.inf)
    branch = int(np.argmin(first))
    if not np.sqrt(first[branch]) < 1e-5:
        raise SingularPoseError(
            f"linear move: the start joints {np.round(q0, 3).tolist()} deg are not a regular "
            "solution of their own pose (singular start configuration)"
        )

    def where(i: int) -> str:
        xyz = np.round(T_path[i, :3, 3], 1).tolist()
        return f"at {xyz} mm ({100.0 * i / (len(T_path) - 1):.0f}% along the path)"

    bad = ~sols.valid[:, branch]
    if bad.any():
        i = int(np.argmax(bad))
        raise UnreachableError(f"linear move leaves the {model.name}'s workspace {where(i)}")
    for flag, name in (
        (sols.wrist_singular, "wrist"),
        (sols.elbow_singular, "elbow"),
        (sols.shoulder_singular, "shoulder"),
    ):
        hit = flag[:, branch]
        if hit.any():
            raise SingularPoseError(
                f"linear move passes near the {model.name}'s {name} singularity "
                f"{where(int(np.argmax(hit)))}; use a joint move or change the tool orientation"
            )
    track = np.unwrap(sols.q[:, branch, :], period=360.0, axis=0)
    track += 360.0 * np.round((q0 - track[0]) / 360.0)
    step = np.max(np.abs(np.diff(track, axis=0)), axis=1)
    if step.size and step.max() > max_step:
        i = int(np.argmax(step))
        raise SingularPoseError(
            f"linear move needs a joint jump of {step[i]:.1f} deg {where(i)}; "
            "use a joint move or change the tool orientation"
        )
    return track, branch


# ---------------------------------------------------------------------------------------------
# Approach and retreat


def offset_pose(
    T: np.ndarray, distance_mm: float, direction: str | np.ndarray = "tool"
) -> np.ndarray:
    """A pose moved `distance_mm` away from T (4, 4) without rotating it.

    direction "tool": back along the tool's own -Z (the usual approach axis of a gripper);
    otherwise a 3-vector in B, e.g. (0, 0, 1) for straight up in an upright base frame.
    """
    out = np.array(T, dtype=float)
    if isinstance(direction, str):
        if direction != "tool":
            raise ValueError(f"direction must be 'tool' or a 3-vector, got {direction!r}")
        axis = -out[:3, 2]
    else:
        axis = np.asarray(direction, dtype=float).reshape(3)
        norm = np.linalg.norm(axis)
        if not norm > 0.0:
            raise ValueError("offset direction must be a non-zero vector")
        axis = axis / norm
    out[:3, 3] += distance_mm * axis
    return out


def plan_approach(
    model: URModel,
    q0_deg: np.ndarray,
    T_target: np.ndarray,
    distance_mm: float,
    limits: MotionLimits | None = None,
    *,
    direction: str | np.ndarray = "tool",
    tool: np.ndarray | None = None,
) -> tuple[Trajectory, Trajectory]:
    """Joint move to a pose `distance_mm` short of T_target, then a linear move onto it."""
    T_pre = offset_pose(T_target, distance_mm, direction)
    q_pre = nearest_solution(
        model, T_pre, q0_deg, tool=tool, allow_singular=False, singular_tol=0.02
    )
    move = plan_joint_move(q0_deg, q_pre, limits, model=model)
    return move, plan_linear_move(model, q_pre, T_target, limits, tool=tool)


def plan_retreat(
    model: URModel,
    q0_deg: np.ndarray,
    distance_mm: float,
    limits: MotionLimits | None = None,
    *,
    direction: str | np.ndarray = "tool",
    tool: np.ndarray | None = None,
) -> Trajectory:
    """Linear move `distance_mm` away from the current tool pose (back along -Z or `direction`)."""
    T = forward(model, np.asarray(q0_deg, dtype=float), tool)
    return plan_linear_move(
        model, q0_deg, offset_pose(T, distance_mm, direction), limits, tool=tool
    )
