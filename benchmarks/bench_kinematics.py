"""Kinematics and motion: vectorised IK/FK throughput and FK(IK) accuracy per UR model.

IK throughput counts poses solved per second with all 8 branches, on 100,000 random poses;
accuracy is the worst flange error of every valid branch over 10,000 random poses per model
(poses made by FK of uniformly random joints in [-180, 180) deg).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.collision import Box, FloorPlane, check_collisions
from omnisort_hw.core.frames import rotation_angle_deg
from omnisort_hw.core.kinematics import (
    UR5E,
    UR_MODELS,
    forward,
    inverse,
    nearest_solutions,
    wrap_deg,
)
from omnisort_hw.core.motion import MotionLimits, plan_joint_move, plan_linear_move

N_SPEED = 100_000
N_ACCURACY = 10_000


def _best_time(func: Callable[[], Any], repeats: int = 3) -> float:
    """Shortest wall time of `repeats` calls, s."""
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        func()
        best = min(best, time.perf_counter() - t0)
    return best


def _accuracy(name: str, rng: np.random.Generator) -> dict[str, Any]:
    """Worst FK(IK) errors over all valid branches, and recovery of the generating joints."""
    model = UR_MODELS[name]
    q = rng.uniform(-180.0, 180.0, (N_ACCURACY, 6))
    T = forward(model, q)
    sols = inverse(model, T)
    back = forward(model, np.where(sols.valid[..., None], sols.q, 0.0))
    pos = np.linalg.norm(back[..., :3, 3] - T[:, None, :3, 3], axis=-1)[sols.valid]
    rot = np.radians(rotation_angle_deg(back[..., :3, :3], T[:, None, :3, :3]))[sols.valid]
    diff = np.abs(wrap_deg(sols.q - q[:, None, :])).max(axis=-1)
    recovered = np.where(sols.valid, diff, np.inf).min(axis=1)
    return {
        f"{name}_fkik_max_pos_err_mm": float(f"{pos.max():.3g}"),
        f"{name}_fkik_max_rot_err_rad": float(f"{rot.max():.3g}"),
        f"{name}_source_joints_max_err_deg": float(f"{recovered.max():.3g}"),
        f"{name}_mean_valid_branches": round(float(sols.valid.sum(axis=1).mean()), 2),
    }


def run(shared: Path) -> dict[str, Any]:
    """Figures of the kinematics and motion rooms (`shared` is unused: no data files needed)."""
    del shared
    rng = np.random.default_rng(20240601)
    out: dict[str, Any] = {}
    q = rng.uniform(-180.0, 180.0, (N_SPEED, 6))
    T = forward(UR5E, q)
    t_fk = _best_time(lambda: forward(UR5E, q))
    t_ik = _best_time(lambda: inverse(UR5E, T))
    t_near = _best_time(lambda: nearest_solutions(UR5E, T, q))
    t_ik_small = _best_time(lambda: inverse(UR5E, T[:1]), repeats=200)
    out["ik_ur5e_poses_per_s_8_branches"] = round(N_SPEED / t_ik)
    out["fk_ur5e_poses_per_s"] = round(N_SPEED / t_fk)
    out["nearest_solution_ur5e_poses_per_s"] = round(N_SPEED / t_near)
    out["ik_single_pose_latency_us"] = round(1e6 * t_ik_small, 1)
    for name in UR_MODELS:
        out.update(_accuracy(name, rng))

    # Motion: a typical 400 mm linear move with a 30 deg turn, a joint move, a collision check.
    home = np.array([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
    target = forward(UR5E, home)
    target[:3, 3] += (-250.0, 250.0, -200.0)
    c, s = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    target[:3, :3] = target[:3, :3] @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    limits = MotionLimits(rate_hz=500.0)
    t_lin = _best_time(lambda: plan_linear_move(UR5E, home, target, limits), repeats=5)
    linear = plan_linear_move(UR5E, home, target, limits)
    t_joint = _best_time(lambda: plan_joint_move(home, linear.q[-1], limits), repeats=5)
    obstacles = [
        Box((-900.0, -900.0, 0.0), (-600.0, -600.0, 300.0), "bin"),
        Box((300.0, -200.0, 0.0), (700.0, 200.0, 250.0), "conveyor"),
        FloorPlane(),
    ]
    t_col = _best_time(lambda: check_collisions(UR5E, linear.q, obstacles), repeats=5)
    out["linear_move_plan_ms"] = round(1e3 * t_lin, 2)
    out["linear_move_samples"] = len(linear)
    out["joint_move_plan_ms"] = round(1e3 * t_joint, 3)
    out["collision_check_samples_per_s"] = round(len(linear) / t_col)
    return out
