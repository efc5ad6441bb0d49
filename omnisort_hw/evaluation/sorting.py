"""The random-scene sorting experiment on the simulated cell (`omnisort evaluate sorting`).

Per scene: the sorting cell with the camera turned by up to +-10 deg about each axis, 3 to 6
cubes of random colours, positions and yaws, one bin per colour. The robot is registered from
the image, the cubes located, picked and placed through the device interfaces by the sort use
case (`pipeline.sort_run`, on the scene's rig), and the result verified from the simulator's state
(`sim_backend.sort_harness.SimVerifier`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.core.registration import pose_error
from omnisort_hw.errors import InputError
from omnisort_hw.evaluation.scene_rig import sort_on_scene
from omnisort_hw.pipeline.calibration_source import MemoryCalibration
from omnisort_hw.runlog import NullLog, RunLog
from omnisort_hw.sweeps.trial import Trial, TrialOutput, merge_paths, split_paths
from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
from sim_backend.scene import (
    NAMED_COLORS,
    Color,
    CubeSpec,
    load_scene,
    sized,
    with_camera_effects,
)
from sim_backend.scene import BinSpec as SceneBin
from sim_backend.sort_harness import (
    SimVerifier,
    scene_T_SB,
    sim_registration_config,
    sim_sort_config,
)

EVAL_COLORS = ("red", "green", "blue", "black")


def draw_layout(
    base: Any,
    rng: np.random.Generator,
    n_cubes: int,
    colors: Sequence[str] = EVAL_COLORS,
    max_angle_deg: float = 10.0,
    min_spacing_mm: float = 220.0,
) -> dict[str, Any]:
    """A random layout (JSON): camera angles (+-max), n cubes [colour, x, y, yaw] of random
    colours, positions and yaws within reach and apart enough for the open gripper."""
    robot = base.robot
    bx, by = robot.base_mm
    placed: list[np.ndarray] = []
    for _ in range(200):
        placed = []
        for _ in range(2000):
            p = np.array([rng.uniform(-420.0, 420.0), rng.uniform(450.0, 830.0)])
            r = float(np.hypot(p[0] - bx, p[1] - by))
            on_board = abs(p[0]) < 280.0 and p[1] > 780.0
            if not 430.0 <= r <= 820.0 or on_board:
                continue
            if any(np.linalg.norm(p - q) < min_spacing_mm for q in placed):
                continue
            placed.append(p)
            if len(placed) == n_cubes:
                break
        if len(placed) == n_cubes:
            break
    else:
        raise InputError(f"cannot place {n_cubes} cubes {min_spacing_mm} mm apart")
    # The draws in the order the experiment always made them: colours, yaws, camera.
    cubes = [
        [str(c), float(p[0]), float(p[1]), float(rng.uniform(0.0, 90.0))]
        for p, c in zip(placed, rng.choice(list(colors), n_cubes), strict=True)
    ]
    ang = rng.uniform(-max_angle_deg, max_angle_deg, 3)
    return {
        "camera": {"roll_deg": float(ang[0]), "pitch_deg": float(ang[1]), "yaw_deg": float(ang[2])},
        "cubes": cubes,
        "bins": list(colors),
    }


def apply_layout(
    base: Any, layout: dict[str, Any], home_deg: Sequence[float] | np.ndarray | None
) -> Any:
    """The base scene with a layout's camera angles, cubes and bins (`draw_layout`)."""
    size = base.cubes[0].size_mm if base.cubes else 100.0
    cubes = tuple(
        CubeSpec(Color(c, NAMED_COLORS[c]), size, (float(x), float(y)), float(yaw))
        for c, x, y, yaw in layout["cubes"]
    )
    bins = tuple(
        SceneBin(Color(c, NAMED_COLORS[c]), b.position_mm, b.size_mm, b.wall_mm, b.yaw_deg)
        for b, c in zip(base.bins, layout["bins"], strict=False)
    )
    robot_changes: dict[str, Any] = {}
    if home_deg is not None:
        robot_changes["home_deg"] = tuple(float(v) for v in home_deg)
    return base.replace(camera=dict(layout["camera"]), cubes=cubes, bins=bins, robot=robot_changes)


def random_scene(
    base: Any,
    rng: np.random.Generator,
    n_cubes: int,
    colors: Sequence[str] = EVAL_COLORS,
    max_angle_deg: float = 10.0,
    home_deg: Sequence[float] | None = None,
    min_spacing_mm: float = 220.0,
) -> Any:
    """The sorting scene with random camera angles (+-max), n cubes of random colours, positions
    and yaws within reach and apart enough for the open gripper, and bins of `colors`."""
    layout = draw_layout(base, rng, n_cubes, colors, max_angle_deg, min_spacing_mm)
    return apply_layout(base, layout, home_deg)


# The headline figures of `evaluate_sorting`, in the order people read them (CLI, benchmark).
SUMMARY_KEYS = (
    "scenes",
    "cubes",
    "sorted_ok",
    "success_rate",
    "collisions",
    "mean_position_error_mm",
    "max_position_error_mm",
    "mean_position_error_B_mm",
    "mean_registration_error_mm",
    "max_registration_error_mm",
    "mean_registration_error_deg",
    "motion_s_per_pick",
    "wait_s_per_pick",
    "gripper_s_per_pick",
    "lower_bound_s_per_pick",
    "picks_per_minute",
    "plan_ms_per_pick",
    "wall_s_per_pick",
)


# Entries of a scene's row that depend on the machine (wall and CPU times), kept apart from
# the result (`split_paths`): everything else depends on the trial's inputs only.
SORTING_TIMING = (
    "wall_s_per_pick",
    "timings_s",
    "cycle.wait_s",
    "cycle.locate_s",
    "cycle.plan_ms_mean",
    "cycle.plan_ms_max",
    "cycle.wait_s_per_pick",
    "cycle.cycle_s_per_pick",
    "cycle.picks_per_minute",
)


def sorting_trials(
    scenes: int = 50,
    seed: int = 0,
    width: int = 960,
    calibration: str = "truth",
    max_angle_deg: float = 10.0,
    cubes: tuple[int, int] = (3, 6),
    effects: bool = False,
) -> list[Trial]:
    """The experiment's scenes as trials: the seeded draws (cube count, layout, calibration
    errors) are made here, in the order the experiment always made them, and written into
    each trial's configuration; a trial's seed is its simulated cell's noise seed.
    `effects`: each scene seen through a real colour camera (the sensor's noise, blur and
    JPEG with crosstalk, chromatic aberration, bloom and Bayer demosaicing:
    `scene.with_camera_effects`), not as clean renders; left out of the configuration when
    False, so the trials made before it keep their identity."""
    if calibration not in ("truth", "perturbed"):
        raise InputError(f"--calibration must be truth or perturbed, got {calibration!r}")
    rng = np.random.default_rng(seed)
    base = sized(load_scene("sorting"), width)
    trials = []
    for k in range(scenes):
        n = int(rng.integers(cubes[0], cubes[1] + 1))
        config: dict[str, Any] = {
            "scene": k,
            "sweep_seed": seed,
            "width": width,
            "calibration": calibration,
            "layout": draw_layout(base, rng, n, max_angle_deg=max_angle_deg),
        }
        if calibration == "perturbed":
            config["calibration_errors"] = draw_calibration_errors(rng)
        if effects:
            config["effects"] = True
        trials.append(Trial("sorting", config, seed * 1000 + k))
    return trials


def sorting_trial(config: Mapping[str, Any], seed: int) -> TrialOutput:
    """One scene: register the robot from the image, locate, sort, verify (the row of
    `summarize_sorting`, its machine-dependent entries in timing)."""
    row = sort_scene(config, seed, NullLog)
    return split_paths(row, SORTING_TIMING)


def sort_scene(config: Mapping[str, Any], seed: int, log: RunLog) -> dict[str, Any]:
    """The scene of `config` sorted on a simulated cell seeded with `seed`; its row."""
    base = sized(load_scene("sorting"), int(config["width"]))
    cfg0 = SortConfig()
    scene = apply_layout(base, config["layout"], cfg0.home_deg)
    k, n = int(config["scene"]), len(config["layout"]["cubes"])
    cfg = sim_sort_config(scene, cfg0)
    reg_cfg = sim_registration_config(scene)
    effects = bool(config.get("effects", False))
    cell = SimCell(with_camera_effects(scene) if effects else scene, seed=seed)
    cam, laser, arm = SimCamera(cell, degraded=effects), SimLaserSwitch(cell), SimArm(cell)
    row: dict[str, Any] = {"scene": k, "cubes": n}
    try:
        for d in (cam, laser, arm):
            d.connect()
        cam.grab(with_truth=True)
        truth = cam.last_truth
        assert truth is not None
        calib = SystemCalibration.from_json(truth, source="truth")
        if "calibration_errors" in config:
            calib = perturbed(calib, config["calibration_errors"])
        verifier = SimVerifier(arm)
        t0 = time.perf_counter()
        report = sort_on_scene(
            (cam, laser, arm),
            MemoryCalibration(calib),
            cfg,
            reg_cfg,
            verifier,
            log,
            clock=lambda: cell.world.sim_time,  # the arm's time, not the PC's
        )
        wall = time.perf_counter() - t0
        assert report.registration is not None
        T_est = np.asarray(report.registration["matrix"], float)
        reg_mm, reg_deg = pose_error(T_est, verifier.T_SB())
        tot = report.totals()
        picks, extra = max(1, tot.sorted), report.extra
        row.update(
            sorted_ok=tot.sorted_ok,
            collisions=tot.collisions,
            position_errors_mm=[o.error_mm for o in report.outcomes if o.error_mm is not None],
            position_errors_B_mm=extra.errors_B_mm or [],
            registration_error_mm=reg_mm,
            registration_error_deg=reg_deg,
            motion_s_per_pick=tot.planned_motion_s_per_pick,
            cycle=extra.cycle or {},
            wall_s_per_pick=wall / picks,
            skipped=[
                o.reason for o in report.outcomes if o.status in ("skipped", "missed", "failed")
            ],
            collision_events=extra.collision_events or [],
            timings_s=extra.timings_s or {},
            checks=extra.checks or [],
        )
    except Exception as exc:
        row.update(sorted_ok=0, collisions=None, error=f"{type(exc).__name__}: {exc}")
    finally:
        for d in (arm, laser, cam):
            d.close()
        cell.close()
    return row


def evaluate_sorting(
    scenes: int = 50,
    seed: int = 0,
    width: int = 960,
    calibration: str = "truth",
    max_angle_deg: float = 10.0,
    cubes: tuple[int, int] = (3, 6),
    progress: Callable[[int, dict[str, Any]], None] | None = None,
    log: RunLog = NullLog,
    effects: bool = False,
) -> dict[str, Any]:
    """The random-scene experiment on the simulated cell, in this process: per scene,
    register the robot from the image, locate, sort, verify against the simulator's state;
    returns the totals (a sweep runs the same trials elsewhere: `sorting_trials`).

    `calibration`: "truth" uses the true camera rotation and laser plane; "perturbed" adds the
    joint method's typical errors (0.1 deg per camera angle, 0.15 deg per laser angle, 3 mm
    laser distance, Gaussian) to emulate a calibrated cell.
    """
    trials = sorting_trials(scenes, seed, width, calibration, max_angle_deg, cubes, effects)
    rows: list[dict[str, Any]] = []
    t_all = time.perf_counter()
    for trial in trials:
        rows.append(sort_scene(trial.config, trial.seed, log))
        if progress is not None:
            progress(len(rows) - 1, rows[-1])
    return summarize_sorting(rows, time.perf_counter() - t_all, seed, width, calibration, effects)


def summarize_rows(rows: Sequence[Mapping[str, Any]], wall_s: float) -> dict[str, Any]:
    """`evaluate_sorting`'s totals from a sweep's sorting rows (manifest order)."""
    if not rows:
        raise InputError("no sorting rows to summarise")
    c = rows[0]["config"]
    scene_rows = [merge_paths(r["result"], r["timing"]) for r in rows]
    return summarize_sorting(
        scene_rows, wall_s, c["sweep_seed"], c["width"], c["calibration"], c.get("effects", False)
    )


def planning_only(scenes: int = 8, seed: int = 0) -> dict[str, Any]:
    """Pick planning alone, one thread, on random scenes (true cube poses, no rendering): the
    picks chained as the sorter chains them (bin -> next cube), each plan's CPU time."""
    from omnisort_hw.core.cube_location import Cube
    from omnisort_hw.core.pick_planning import Planner

    rng = np.random.default_rng(seed)
    base = sized(load_scene("sorting"), 320)
    cfg0 = SortConfig()
    times: list[float] = []
    planned = refused = 0
    motion = 0.0
    for _ in range(scenes):
        scene = random_scene(base, rng, int(rng.integers(3, 7)), home_deg=cfg0.home_deg)
        cfg = sim_sort_config(scene, cfg0)
        yaw = scene.robot.base_yaw_deg
        T_SB = scene_T_SB(scene)
        T_BS = np.linalg.inv(T_SB)
        cubes = []
        for spec in scene.cubes:
            p_S = np.array([*spec.position_mm, scene.floor_z + spec.size_mm / 2.0])
            p_B = T_BS[:3, :3] @ p_S + T_BS[:3, 3]
            y = spec.yaw_deg - yaw
            cubes.append(
                Cube(spec.color.name, p_S, p_B, y, y, (0, 0), 0.2, 0.3, 800, 100, 0, (0,) * 4)
            )
        planner = Planner(cfg, T_SB)
        q = np.asarray(cfg.home_deg, float)
        left = list(cubes)
        for cube in cubes:
            left.remove(cube)
            t0 = time.thread_time()  # CPU time: one core's work, whatever the machine's load
            plan = planner.plan_pick(cube, left, q, end_home=False)
            times.append(time.thread_time() - t0)
            if plan.refused is not None:
                refused += 1
                left.append(cube)
                continue
            planner.commit(plan)
            planned += 1
            motion += plan.duration_s
            if plan.end_q is not None:  # a plan without moves leaves the arm where it is
                q = plan.end_q
    ms = 1e3 * np.asarray(times)
    return {
        "plans": len(times),
        "planned": planned,
        "refused": refused,
        "plan_ms_mean": round(float(ms.mean()), 1),
        "plan_ms_p95": round(float(np.percentile(ms, 95)), 1),
        "plan_ms_max": round(float(ms.max()), 1),
        "planned_motion_s_per_pick": round(motion / max(1, planned), 3),
    }


CALIBRATION_ERROR_SD = {
    "cam_roll_deg": 0.1,
    "cam_pitch_deg": 0.1,
    "cam_yaw_deg": 0.1,
    "laser_roll_deg": 0.15,
    "laser_pitch_deg": 0.15,
    "laser_distance_mm": 3.0,
}


def draw_calibration_errors(rng: np.random.Generator) -> dict[str, float]:
    """Gaussian errors of the joint method's typical size, one per calibrated figure."""
    return {k: float(rng.normal(0.0, sd)) for k, sd in CALIBRATION_ERROR_SD.items()}


def perturbed(calib: SystemCalibration, errors: Mapping[str, float]) -> SystemCalibration:
    """The calibration with `errors` added to its figures (`draw_calibration_errors`)."""
    noisy = {k: v + float(errors[k]) for k, v in calib.parameters().items()}
    return SystemCalibration.from_angles(
        calib.model, noisy, "perturbed", target=calib.target, std=dict(CALIBRATION_ERROR_SD)
    )


def perturb_calibration(calib: SystemCalibration, rng: np.random.Generator) -> SystemCalibration:
    """The calibration with Gaussian errors of the joint method's typical size."""
    return perturbed(calib, draw_calibration_errors(rng))


def summarize_sorting(
    rows: Sequence[dict[str, Any]],
    wall_s: float,
    seed: int,
    width: int,
    calibration: str,
    effects: bool = False,
) -> dict[str, Any]:
    """Totals of the random-scene experiment (the keys `evaluate sorting --json` prints)."""
    cubes = int(sum(r["cubes"] for r in rows))
    ok = int(sum(r.get("sorted_ok", 0) for r in rows))
    coll = [r["collisions"] for r in rows if r.get("collisions") is not None]
    errs = [e for r in rows for e in r.get("position_errors_mm", [])]
    errs_b = [e for r in rows for e in r.get("position_errors_B_mm", [])]
    reg = [r["registration_error_mm"] for r in rows if "registration_error_mm" in r]
    reg_deg = [r["registration_error_deg"] for r in rows if "registration_error_deg" in r]
    cyc = [r["cycle"] for r in rows if r.get("cycle", {}).get("picks")]
    picks = sum(c["picks"] for c in cyc)

    def per_pick(key: str) -> float | None:
        return round(sum(c[key] for c in cyc) / picks, 4) if picks else None

    motion, wait, grip = per_pick("motion_s"), per_pick("wait_s"), per_pick("gripper_s")
    parts = (motion, wait, grip)
    cycle_s = sum(parts) if all(v is not None for v in parts) else None  # type: ignore[arg-type]
    plan_ms = [c["plan_ms_mean"] * c["plans"] for c in cyc if c.get("plan_ms_mean") is not None]
    n_plans = sum(c["plans"] for c in cyc if c.get("plan_ms_mean") is not None)
    wall_pick = [r["wall_s_per_pick"] for r in rows if "wall_s_per_pick" in r]

    def mean(v: Sequence[float]) -> float | None:
        return round(float(np.mean(v)), 4) if v else None

    stages = sorted({k for r in rows for k in r.get("timings_s", {})})
    timings = {
        k: mean([r["timings_s"][k] for r in rows if k in r.get("timings_s", {})]) for k in stages
    }

    def pmax(v: Sequence[float]) -> float | None:
        return round(float(np.max(v)), 4) if v else None

    seen = {"effects": True} if effects else {}  # through the colour camera: said when so
    return {
        "scenes": len(rows),
        "seed": seed,
        "width": width,
        "calibration": calibration,
        **seen,
        "cubes": cubes,
        "sorted_ok": ok,
        "success_rate": round(ok / cubes, 4) if cubes else None,
        "collisions": int(sum(coll)),
        "scenes_failed": sum("error" in r for r in rows),
        "mean_position_error_mm": mean(errs),
        "max_position_error_mm": pmax(errs),
        "mean_position_error_B_mm": mean(errs_b),
        "mean_registration_error_mm": mean(reg),
        "max_registration_error_mm": pmax(reg),
        "mean_registration_error_deg": mean(reg_deg),
        "motion_s_per_pick": motion,
        "wait_s_per_pick": wait,
        "gripper_s_per_pick": grip,
        "lower_bound_s_per_pick": per_pick("planned_s"),
        "cycle_s_per_pick": round(cycle_s, 4) if cycle_s else None,
        "picks_per_minute": round(60.0 / cycle_s, 2) if cycle_s else None,
        "plan_ms_per_pick": round(sum(plan_ms) / n_plans, 1) if n_plans else None,
        "plan_ms_max": max((c["plan_ms_max"] for c in cyc if c.get("plan_ms_max")), default=None),
        "locate_s_per_pick": per_pick("locate_s"),
        "wall_s_per_pick": mean(wall_pick),
        "wall_s": round(wall_s, 1),
        "stage_wall_s_per_scene": timings,
        "checks": sum(len(r.get("checks", [])) for r in rows),
        "checks_located_again": sum(
            bool(c.get("located_again")) for r in rows for c in r.get("checks", [])
        ),
        "not_sorted": [
            {"scene": r["scene"], "reasons": r.get("skipped", []), "error": r.get("error")}
            for r in rows
            if r.get("sorted_ok", 0) < r["cubes"] or "error" in r
        ],
        "collision_events": [
            {"scene": r["scene"], "events": r["collision_events"]}
            for r in rows
            if r.get("collision_events")
        ],
    }
