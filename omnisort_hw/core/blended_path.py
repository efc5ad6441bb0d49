"""Blended paths: consecutive moves that do not stop at their via points (UR's blend radius).

A path is a list of segments, joint or linear moves planned by `core.motion` each from the end
of the previous one, with a blend radius (mm, at the TCP) at every via point. A controller
blends by starting the next move before the previous one has stopped: here the two moves
overlap in time and the joints follow the sum of both trajectories (the previous move's
braking superposed on the next move's start). The overlap is as long as both moves stay
within the blend radius of their shared via point (the TCP neither leaves the previous move
nor joins the next one outside that sphere), at most half of either move, and is shortened
until the summed joint speeds and accelerations stay within the two moves' limits. Outside
the overlap windows the path is exactly its moves, so only the windows need a new collision
check (`BlendedPath.windows`). A blend radius of 0 stops at the via point.

Paths are planned at one rate (`PATH_RATE_HZ`, the rate the planner plans and collision-checks
its moves at) whoever plays them, and `resample`d to the player's own rate by linear
interpolation in joint space, so every played sample lies on the joint-space segments between
planned samples that the collision check covers, and the simulated arm (240 Hz physics) and the
emulated controller (500 Hz) play the same path in the same time to within one simulator step.
A segment may bring its move as already planned (and checked) at that rate: it is used as is.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from omnisort_hw.core.kinematics import URModel, forward
from omnisort_hw.core.motion import MotionLimits, Trajectory, plan_joint_move, plan_linear_move

__all__ = [
    "PATH_RATE_HZ",
    "BlendedPath",
    "Segment",
    "plan_blended_path",
    "resample",
]

PATH_RATE_HZ = MotionLimits().rate_hz
# A blend is shortened by this factor until the summed joint rates are within limits.
_SHRINK = 0.8
# Relative slack on the joint-rate check of a window (finite differences of exact samples).
_RATE_SLACK = 1e-3


@dataclass(frozen=True)
class Segment:
    """One move of a path: "joint" to joints `target` (6,) deg or "linear" to the TCP pose
    `target` (4, 4) mm, at `limits`, blending into the next move within `blend_mm` of its
    target (0: stop there; the last segment's blend is ignored)."""

    kind: str
    target: np.ndarray
    limits: MotionLimits
    blend_mm: float = 0.0
    planned: Trajectory | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in ("joint", "linear"):
            raise ValueError(f"segment kind must be 'joint' or 'linear', got {self.kind!r}")
        if not (np.isfinite(self.blend_mm) and self.blend_mm >= 0.0):
            raise ValueError(f"blend radius must be finite and >= 0 mm, got {self.blend_mm}")


@dataclass(frozen=True)
class BlendedPath:
    """The blended trajectory, its moves (each as planned alone, at rest at both ends), the
    sample each move starts at and the overlap (samples) at each via point."""

    trajectory: Trajectory
    moves: tuple[Trajectory, ...]
    starts: np.ndarray
    overlaps: np.ndarray

    @property
    def duration(self) -> float:
        return self.trajectory.duration

    @property
    def stopped_duration(self) -> float:
        """The same moves with a stop at every via point, s."""
        return float(sum(m.duration for m in self.moves))

    def windows(self) -> list[tuple[int, int, int]]:
        """(first, last sample, via point k) of every overlap window of the trajectory."""
        out = []
        for k, m in enumerate(self.overlaps):
            if m > 0:
                first = int(self.starts[k + 1])
                out.append((first, first + int(m), k))
        return out


def _plan_move(
    model: URModel, q0: np.ndarray, seg: Segment, tool: np.ndarray | None, rate_hz: float
) -> Trajectory:
    pre = seg.planned
    if (
        pre is not None
        and len(pre) > 1
        and np.allclose(pre.q[0], q0, atol=1e-9)
        and abs((pre.t[1] - pre.t[0]) * rate_hz - 1.0) < 1e-9
    ):
        return pre
    limits = replace(seg.limits, rate_hz=rate_hz)
    if seg.kind == "joint":
        return plan_joint_move(q0, np.asarray(seg.target, float), limits, model=model)
    return plan_linear_move(model, q0, np.asarray(seg.target, float), limits, tool=tool)


def _inside_run(p: np.ndarray, c: np.ndarray, r: float, from_end: bool) -> int:
    """Samples (beyond the via point itself) of the run of TCP points p (M, 3) within r of c
    that touches the via point: at the end of p (from_end) or at its start."""
    inside = np.linalg.norm(p - c, axis=1) <= r
    if from_end:
        inside = inside[::-1]
    out = np.flatnonzero(~inside)
    return int(out[0]) - 1 if out.size else len(p) - 1


def _window(a: Trajectory, b: Trajectory, m: int, pad: int = 2) -> np.ndarray:
    """Joints of a followed by b overlapping by m samples, from `pad` samples before the
    overlap to `pad` after it."""
    la = len(a)
    i = np.arange(la - 1 - m - pad, la + pad)  # indices on a's timeline
    qa = a.q[np.clip(i, 0, la - 1)]
    j = i - (la - 1 - m)
    qb = b.q[np.clip(j, 0, len(b) - 1)] - b.q[0]
    return qa + qb


def _rates_ok(
    a: Trajectory, b: Trajectory, m: int, v: np.ndarray, acc: np.ndarray, dt: float
) -> bool:
    w = _window(a, b, m)
    qd = np.diff(w, axis=0) / dt
    qdd = np.diff(qd, axis=0) / dt
    return bool(
        np.all(np.abs(qd) <= v * (1.0 + _RATE_SLACK)) and np.all(np.abs(qdd) <= acc * (1 + 0.01))
    )


def _rate_caps(
    model: URModel, traj: Trajectory, seg: Segment, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Joint speed and acceleration a move may use: its limits (capped at the hardware), or
    what it already uses where a linear move's grid estimate runs a little over."""
    v = np.minimum(seg.limits.joint_speed, np.asarray(model.max_speed_deg_s, float))
    acc = seg.limits.joint_acc
    if len(traj) > 2:
        qd = np.diff(traj.q, axis=0) / dt
        v = np.maximum(v, np.max(np.abs(qd), axis=0))
        acc = np.maximum(acc, np.max(np.abs(np.diff(qd, axis=0) / dt), axis=0))
    return v, acc


def plan_blended_path(
    model: URModel,
    q0_deg: np.ndarray,
    segments: Sequence[Segment],
    *,
    tool: np.ndarray | None = None,
    rate_hz: float = PATH_RATE_HZ,
) -> BlendedPath:
    """The blended path from joints q0 (6,) deg through `segments` (see module).

    Raises what `plan_joint_move` / `plan_linear_move` raise for a move that cannot be planned
    (the move is then refused as it would be alone)."""
    if not segments:
        raise ValueError("a blended path needs at least one segment")
    q = np.asarray(q0_deg, float).reshape(6)
    moves: list[Trajectory] = []
    for seg in segments:
        traj = _plan_move(model, q, seg, tool, rate_hz)
        moves.append(traj)
        q = traj.q[-1]
    dt = 1.0 / rate_hz
    caps = [_rate_caps(model, m, s, dt) for m, s in zip(moves, segments, strict=True)]
    overlaps = np.zeros(len(moves) - 1, dtype=int)
    for k in range(len(moves) - 1):
        a, b, r = moves[k], moves[k + 1], float(segments[k].blend_mm)
        if r <= 0.0 or len(a) < 3 or len(b) < 3:
            continue
        pa = forward(model, a.q, tool)[:, :3, 3]
        pb = forward(model, b.q, tool)[:, :3, 3]
        m = min(
            _inside_run(pa, pa[-1], r, from_end=True),
            _inside_run(pb, pb[0], r, from_end=False),
            (len(a) - 1) // 2,
            (len(b) - 1) // 2,
        )
        v = np.maximum(caps[k][0], caps[k + 1][0])
        acc = np.maximum(caps[k][1], caps[k + 1][1])
        while m > 0 and not _rates_ok(a, b, m, v, acc, dt):
            m = int(m * _SHRINK)
        overlaps[k] = max(m, 0)
    lengths = np.array([len(m) for m in moves])
    starts = np.concatenate([[0], np.cumsum(lengths[:-1] - 1 - overlaps)])
    n = int(starts[-1] + lengths[-1])
    i = np.arange(n)
    qs = np.repeat(moves[0].q[:1], n, axis=0)
    for s, mv in zip(starts, moves, strict=True):
        qs += mv.q[np.clip(i - s, 0, len(mv) - 1)] - mv.q[0]
    qs[-1] = moves[-1].q[-1]
    traj = Trajectory(t=i * dt, q=qs, kind="blended")
    return BlendedPath(traj, tuple(moves), starts, overlaps)


def resample(traj: Trajectory, rate_hz: float) -> Trajectory:
    """The trajectory at `rate_hz`, stretched to a whole number of periods (which only lowers
    speeds and accelerations); it starts and ends on the same samples."""
    duration = traj.duration
    n = max(1, int(np.ceil(duration * rate_hz - 1e-9))) if duration > 0 else 0
    if n == 0:
        return Trajectory(t=np.zeros(1), q=traj.q[:1].copy(), kind=traj.kind)
    t = np.arange(n + 1) / rate_hz
    src = t * (duration / t[-1])
    q = np.stack([np.interp(src, traj.t, traj.q[:, j]) for j in range(6)], axis=1)
    q[0], q[-1] = traj.q[0], traj.q[-1]
    return Trajectory(t=t, q=q, kind=traj.kind)
