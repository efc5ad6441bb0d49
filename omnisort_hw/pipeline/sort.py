"""Sorting: capture, locate the cubes, plan and execute one pick-and-place per cube.

The run talks to the cell only through the device interfaces (`drivers.base`: Camera,
LaserSwitch, Arm with its Gripper), so it runs the same on the simulated and the real cell.
Planning is the core's (`core.pick_planning`): every move of a pick is planned and
collision-checked before the first move of that pick is sent; cubes that cannot be sorted are
reported with the reason and never approached. Motion is refused unless the calibration is
usable (present, intact, recent, robot registered: `pipeline.calibration_source`).

Whoever knows more than the devices show (the simulated cell knows the truth) joins through
the callbacks `on_located` and `on_done` of `Sorter.run`; the run itself never reads truth.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from drivers.base import Waypoint
from omnisort_hw.config.sorting import RegistrationConfig, SortSection
from omnisort_hw.core.cube_location import Cube
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import Move, PickPlan, Planner, SortConfig
from omnisort_hw.errors import ConfigError, MotionRefusedError
from omnisort_hw.pipeline.calibration_source import CalibrationSource, robot_base_T
from omnisort_hw.pipeline.locate import Located, locate_in_images, locate_settings_for
from omnisort_hw.pipeline.pick_cycle import Compute, CycleTimes, InCaller, PickQueue
from omnisort_hw.pipeline.registration import register_from_image
from omnisort_hw.pipeline.scene_check import ChangeWatch, SceneCheck
from omnisort_hw.pipeline.sort_report import MAX_REACHED, CubeOutcome, SortReport
from omnisort_hw.runlog import NullLog, RunLog

if TYPE_CHECKING:
    from drivers.base import Arm, Camera, LaserSwitch

JOINT_AT_TOLERANCE_DEG = 0.5


class SortVerifier(Protocol):
    """Checks a run against what the cell really did (the simulated cell's truth)."""

    def start(self) -> None: ...

    def stop(self) -> None: ...

    def on_located(self, loc: Located) -> None: ...

    def on_done(self, report: SortReport, loc: Located) -> None: ...


class SceneLayout(Protocol):
    """What a backend that knows its scene tells the sorting (the simulated cell does)."""

    def sort_config(self, base: SortConfig) -> SortConfig: ...

    def registration_config(self) -> RegistrationConfig: ...

    def verifier(self) -> SortVerifier: ...


def resolve_sorting(
    section: SortSection | None,
    registration: RegistrationConfig | None,
    scene: SceneLayout | None,
) -> tuple[SortConfig, RegistrationConfig | None]:
    """The `[sorting]` and `[registration]` records to sort with; `from_scene` takes what the
    file leaves out from the scene of the cell's backend (and its floor board, when there is
    no `[registration]`)."""
    if section is None:
        raise ConfigError(
            "[sorting]: missing; the sorting pipeline needs it (bins, obstacles, cube size, "
            "home pose; or from_scene = true on the simulated cell)"
        )
    cfg = section.resolve(scene.sort_config(SortConfig()) if scene is not None else None)
    if registration is None and section.from_scene and scene is not None:
        registration = scene.registration_config()
    return cfg, registration


class Sorter:
    """Runs the sorting cell through its device interfaces (see module docstring)."""

    def __init__(
        self,
        camera: Camera,
        arm: Arm | None,
        laser: LaserSwitch | None,
        calibration: CalibrationSource,
        cfg: SortConfig,
        registration: RegistrationConfig | None = None,
        log: RunLog = NullLog,
        cancel: threading.Event | None = None,
        progress: Callable[[dict[str, Any]], None] | None = None,
        on_pick: Callable[[str, CubeOutcome], None] | None = None,
        clock: Callable[[], float] | None = None,
        compute: Compute | None = None,
        check_changes: bool = True,
        acquire: Callable[[], tuple[np.ndarray, np.ndarray | None, dict[str, Any]]] | None = None,
        laser_color: str = "red",
    ) -> None:
        self.camera = camera
        self.laser_color = laser_color  # the laser's, what its stripe is
        # the cycle's images from a measurement capture (`pipeline.sort_capture`), if given
        self.acquire = acquire
        self.last_capture: dict[str, Any] | None = None
        self.arm = arm
        self.laser = laser
        self.calibration = calibration
        self.cfg = cfg
        self.registration = registration
        self.log = log
        self.cancel = cancel or threading.Event()
        self.progress = progress
        self.on_pick = on_pick  # pick phases: grasping, holding, released, empty
        self._executed: list[np.ndarray] = []
        self.clock = clock or time.monotonic
        self.cycle: CycleTimes | None = None
        self._ahead: Future[tuple[int, PickPlan] | None] | None = None
        # Location and planning run here: the service's compute worker, else this process.
        self.compute: Compute = compute or InCaller()
        self.check_changes = check_changes  # a check capture once each cube is lifted
        self._watch: ChangeWatch | None = None

    # -- capture and location -------------------------------------------------------------

    def capture(self) -> tuple[np.ndarray, np.ndarray | None]:
        """A laser-off colour image and, with a laser switch and `use_laser`, a laser-on one."""
        laser_img = None
        if self.acquire is not None and self.laser is not None and self.cfg.use_laser:
            colour, laser_img, self.last_capture = self.acquire()
            self.log.image("sorting/image", colour)
            if laser_img is not None:
                self.log.image("sorting/laser_image", laser_img)
            return colour, laser_img
        if self.laser is not None:
            self.laser.off()
        colour = self.camera.grab().image
        if self.laser is not None and self.cfg.use_laser:
            self.laser.on()
            try:
                laser_img = self.camera.grab().image
            finally:
                self.laser.off()
        self.log.image("sorting/image", colour)
        if laser_img is not None:
            self.log.image("sorting/laser_image", laser_img)
        return colour, laser_img

    def locate(
        self,
        images: tuple[np.ndarray, np.ndarray | None] | None = None,
        register: bool = False,
        calib: SystemCalibration | None = None,
    ) -> Located:
        """Capture (or use `images`), optionally register the robot, and locate the cubes."""
        calib = calib or self.calibration.system()
        t0 = time.perf_counter()
        colour, laser_img = images if images is not None else self.capture()
        t1 = time.perf_counter()
        reg = None
        if register:
            if self.registration is None:
                raise ConfigError("[registration]: needed to register the robot from the image")
            reg = self.compute.call_logged(
                register_from_image,
                self.log,
                colour,
                calib,
                self.registration,
                cancel=self.cancel,
                what="robot registration",
            )
            T_SB = reg.T_SB
        else:
            T_SB = robot_base_T(calib)
        t2 = time.perf_counter()
        robot_base = reg.record() if reg else calib.robot_base
        cubes, diag = self.compute.call_logged(
            locate_in_images,
            self.log,
            colour,
            laser_img,
            calib,
            self.cfg,
            T_SB,
            robot_base,
            laser_color=self.laser_color,
            cancel=self.cancel,
            what="cube location",
        )
        if self.last_capture is not None and images is None:
            diag["capture"] = self.last_capture
        diag["timings_s"] = {
            "capture": t1 - t0,
            "register": t2 - t1,
            "locate": time.perf_counter() - t2,
        }
        return Located(cubes, T_SB, calib, reg, diag, colour)

    # -- the run ----------------------------------------------------------------------------

    def _require_arm(self) -> Arm:
        if self.arm is None:
            raise MotionRefusedError("sort: no arm in this cell's configuration ([arm] section)")
        return self.arm

    def _at(self, q: np.ndarray) -> bool:
        arm = self._require_arm()
        cur = np.asarray(arm.joint_positions(), float)
        return bool(np.max(np.abs(cur - q)) <= JOINT_AT_TOLERANCE_DEG)

    def _planner(self, T_SB: np.ndarray) -> Planner:
        arm = self._require_arm()
        lim = arm.limits
        joint_lim = np.stack([np.asarray(lim.joint_min_deg), np.asarray(lim.joint_max_deg)], 1)
        caps = (lim.max_joint_speed_deg_s, lim.max_joint_accel_deg_s2)
        return Planner(self.cfg, T_SB, joint_lim, lim.check_position, linear_joint_caps=caps)

    def run(
        self,
        max_objects: int | None = None,
        colors: Sequence[str] | None = None,
        register: bool = False,
        on_located: Callable[[Located], None] | None = None,
        on_done: Callable[[SortReport, Located], None] | None = None,
    ) -> SortReport:
        """Sort every cube found (or `max_objects`, or only `colors`); returns the report.

        `on_located` is called once the cubes are located (before any pick), `on_done` with
        the report before it is returned (a harness that knows the truth fills it in there)."""
        t0 = time.perf_counter()
        arm = self._require_arm()
        self.calibration.check_motion_allowed()
        arm.safety_status().raise_if_stopped(arm.name)
        calib = self.calibration.system()
        home = np.asarray(self.cfg.home_deg, float)
        if not register:
            T_SB = robot_base_T(calib)
            if not self._at(home):
                self._go_home(self._planner(T_SB))
            loc = self.locate(calib=calib)
        else:
            loc = self.locate(calib=calib, register=True)
            if not self._at(home):
                self._go_home(self._planner(loc.T_SB))
                loc = self.locate(calib=calib, register=True)
        if on_located is not None:
            on_located(loc)
        cycle = self.cycle = CycleTimes(locate_s=self._locate_s(loc))
        planner = self._planner(loc.T_SB)

        def outcome_of(i: int, cube: Cube) -> tuple[CubeOutcome, bool]:
            """Cube i's outcome before it is picked, and whether it is to pick."""
            out = CubeOutcome(
                i,
                cube.color,
                cube.center_S.tolist(),
                cube.center_B.tolist(),
                cube.yaw_B_deg,
                cube.sigma_mm,
                "skipped",
                "",
                bin_color(self.cfg, cube.color),
            )
            if colors is not None and cube.color not in colors:
                out.reason = f"colour {cube.color!r} not requested"
                return out, False
            return out, True

        made = [outcome_of(i, cube) for i, cube in enumerate(loc.cubes)]
        outcomes = [out for out, _ in made]
        todo = [out.index for out, to_pick in made if to_pick]

        def refused(i: int, reason: str) -> None:
            outcomes[i].status, outcomes[i].reason = "skipped", reason
            self.log.event("sorting/plan", f"cube {i} ({outcomes[i].color}): refused: {reason}")

        queue = PickQueue(planner, loc.cubes, todo, refused, self.cancel.is_set)
        if self.progress is not None:
            self.progress({"located": len(loc.cubes), "to_pick": len(todo)})
        t_exec = time.perf_counter()
        done = 0
        self._watch = self._change_watch(loc, planner, outcome_of) if self.check_changes else None
        with ThreadPoolExecutor(1, thread_name_prefix="plan-ahead") as ahead:
            job = self._plan_now(queue, np.asarray(arm.joint_positions(), float))
            while job is not None:
                i, plan = job
                out = outcomes[i]
                if (max_objects is not None and done >= max_objects) or self.cancel.is_set():
                    queue.give_back(i, plan)
                    break
                out.status, out.reason = "planned", ""
                self.log.event("sorting/plan", f"cube {i} ({out.color}): {plan.duration_s:.1f} s")
                end_q = plan.end_q
                if end_q is None:  # the planner gives every pick its moves
                    raise MotionRefusedError(f"cube {i}: a pick plan without moves")
                self._ahead = ahead.submit(queue.next_plan_via, self.compute, end_q, self.cancel)
                self._execute(plan, out, planner)
                done += 1
                if self.progress is not None:
                    self.progress(
                        {
                            "cube": out.index,
                            "status": out.status,
                            "color": out.color,
                            "bin": out.bin,
                            "reason": out.reason,
                        }
                    )
                t_wait = time.perf_counter()
                nxt = self._join_ahead()
                changed = self._watch is not None and self._watch.settle(queue, nxt, outcomes)
                cycle.wait_s += time.perf_counter() - t_wait
                cycle.picks += out.status == "sorted"
                if out.status == "sorted" and not changed:
                    job = nxt
                else:  # the arm went home or the scene changed: plan again from here
                    if nxt is not None and not changed:
                        queue.give_back(*nxt)
                    if out.status != "sorted":
                        queue.gone.discard(i)  # the cube is an obstacle again
                    job = self._plan_now(queue, np.asarray(arm.joint_positions(), float))
        if self._watch is not None:
            self._watch.close()
        for i, reason in queue.waiting().items():
            out = outcomes[i]
            out.status = "skipped"
            out.reason = (
                "cancelled"
                if self.cancel.is_set()
                else MAX_REACHED
                if max_objects is not None and done >= max_objects
                else reason
            )
        if not self.cancel.is_set() and not self._at(home):
            self._go_home(planner)  # parked out of the camera's view for the next capture
        cycle.plan_s = queue.plan_s
        t_plan = float(sum(queue.plan_s))
        report = SortReport(
            outcomes,
            registration=loc.registration.record() if loc.registration else None,
            rejected_blobs=len(loc.diagnostics.get("rejected", [])),
        )
        report.extra.timings_s = {
            **{k: round(v, 3) for k, v in loc.diagnostics.get("timings_s", {}).items()},
            "plan": round(t_plan, 3),
            "execute": round(time.perf_counter() - t_exec, 3),
        }
        report.extra.cycle = cycle.summary()
        if self._watch is not None:
            report.extra.checks = self._watch.results
        if "capture" in loc.diagnostics:
            report.extra.capture = loc.diagnostics["capture"]
        if on_done is not None:
            on_done(report, loc)
        report.wall_s = time.perf_counter() - t0
        return report

    def _change_watch(
        self,
        loc: Located,
        planner: Planner,
        outcome_of: Callable[[int, Cube], tuple[CubeOutcome, bool]],
    ) -> ChangeWatch:
        """The checks after each release against this location (see `scene_check`)."""
        robot_base = loc.registration.record() if loc.registration else loc.calib.robot_base

        def relocate(image: np.ndarray) -> list[Cube]:
            args = (image, None, loc.calib, self.cfg, loc.T_SB, robot_base)
            cubes, _ = self.compute.call_logged(
                locate_in_images, self.log, *args, cancel=self.cancel, what="re-location"
            )
            return list(cubes)

        settings = locate_settings_for(self.cfg, loc.calib, robot_base)
        check = SceneCheck(
            list(loc.cubes), loc.image, self.cfg, loc.calib, loc.T_SB, planner, settings
        )
        arm = self._require_arm()
        return ChangeWatch(check, self.camera, arm, relocate, self.log, outcome_of)

    def _locate_s(self, loc: Located) -> float:
        """Capture and locate time the parked arm waited for (registration excluded: it is a
        commissioning step, not part of the cycle)."""
        t = loc.diagnostics.get("timings_s", {})
        return float(t.get("capture", 0.0) + t.get("locate", 0.0))

    def _plan_now(self, queue: PickQueue, q: np.ndarray) -> tuple[int, PickPlan] | None:
        """Plan the next pick while the arm waits (the first pick, or after a failed one)."""
        t0 = time.perf_counter()
        job = queue.next_plan_via(self.compute, q, self.cancel)
        if self.cycle is not None:
            self.cycle.wait_s += time.perf_counter() - t0
        return job

    def _join_ahead(self) -> tuple[int, PickPlan] | None:
        """The plan computed while the arm moved (waiting for it if it is not ready)."""
        fut, self._ahead = self._ahead, None
        return fut.result() if fut is not None else None

    def _go_home(self, planner: Planner) -> None:
        arm = self._require_arm()

        q = np.asarray(arm.joint_positions(), float)
        for move in planner.plan_joint_via(q, planner.home, planner.static, "move home"):
            self._send(move)

    def _arm_at_start(self, move: Move) -> Arm:
        """The arm, if the sort goes on and the arm is where `move` starts (else nothing is
        sent: `MotionRefusedError`)."""
        arm = self._require_arm()
        if self.cancel.is_set():
            raise MotionRefusedError("sort cancelled")
        cur = np.asarray(arm.joint_positions(), float)
        off = float(np.max(np.abs(cur - move.traj.q[0])))
        if off > JOINT_AT_TOLERANCE_DEG:
            raise MotionRefusedError(
                f"{move.what}: the arm is not where the plan starts (off by {off:.2f} deg); "
                "nothing sent"
            )
        return arm

    def _moved(self, arm: Arm, t0: float, planned_s: float) -> None:
        """Count a motion begun at `t0` (arm clock) against its planned time, and log where
        the tool ended."""
        if self.cycle is not None:
            self.cycle.motion_s += self.clock() - t0
            self.cycle.planned_s += planned_s
        tcp = np.asarray(arm.tcp_pose(), float)
        self.log.pose("sorting/executed/tcp", tcp)
        self._executed.append(tcp[:3, 3])
        self.log.points3d("sorting/executed/tcp_B", np.array(self._executed), radius=5.0)

    def _send(self, move: Move) -> None:
        """Execute one planned move (the arm plans the same path again and checks its limits)."""
        arm = self._arm_at_start(move)
        log_trajectory(self.log, "sorting/planned", move)
        t0 = self.clock()
        if move.kind == "joint":
            arm.move_joints(
                move.q_target,
                speed_deg_s=self.cfg.joint_speed_deg_s,
                accel_deg_s2=self.cfg.joint_accel_deg_s2,
            )
        else:
            assert move.T_target is not None
            arm.move_linear(
                move.T_target,
                speed_mm_s=self.cfg.linear_speed_mm_s,
                accel_mm_s2=self.cfg.linear_accel_mm_s2,
            )
        self._moved(arm, t0, move.traj.duration)

    def _send_path(self, moves: list[Move], planned_s: float | None) -> None:
        """Execute planned moves as one blended path (each move blends into the next within
        its `blend_mm`, as planned and checked); the arm plans the same path again."""
        if all(m.blend_mm <= 0.0 for m in moves[:-1]):  # nothing to blend: single moves
            for move in moves:
                self._send(move)
            return
        arm = self._arm_at_start(moves[0])
        cfg = self.cfg
        path = []
        for move in moves:
            log_trajectory(self.log, "sorting/planned", move)
            if move.kind == "joint":
                target: object = move.q_target
                speed, accel = cfg.joint_speed_deg_s, cfg.joint_accel_deg_s2
            else:
                target, speed, accel = move.T_target, cfg.linear_speed_mm_s, cfg.linear_accel_mm_s2
            path.append(Waypoint(move.kind, target, speed, accel, move.blend_mm))
        t0 = self.clock()
        arm.move_path(path)
        self._moved(
            arm, t0, planned_s if planned_s is not None else sum(m.traj.duration for m in moves)
        )

    def _grip(self, close: bool) -> None:
        """Close or open the gripper, timed on the arm's clock (an open gripper is not
        opened again)."""
        grip = self._require_arm().gripper
        if not close and not grip.is_closed:
            return
        t0 = self.clock()
        grip.close() if close else grip.open()
        if self.cycle is not None:
            self.cycle.gripper_s += self.clock() - t0

    def _execute(self, plan: PickPlan, out: CubeOutcome, planner: Planner) -> None:
        """Run one planned pick; a grasp that holds nothing is reported and the arm goes home."""
        arm = self._require_arm()
        grip = arm.gripper
        assert plan.descend is not None and plan.lift is not None
        self.log.event("sorting/pick", f"cube {out.index} ({out.color}) -> bin {out.bin}")
        phase = self.on_pick or (lambda _phase, _out: None)
        try:
            self._grip(False)
            paths = plan.paths
            self._send_path(paths["reach"], plan.paths_s.get("reach"))
            phase("grasping", out)
            self._grip(True)
            if grip.holding is False:
                out.status, out.reason = "failed", "the gripper closed on nothing"
                self._grip(False)
                phase("empty", out)
                self._send(plan.lift)
                self._go_home(planner)
                return
            phase("holding", out)
            if self._watch is not None:  # the check capture overlaps the lift and carry
                self._watch.capture_now()
            self._send_path(paths["carry"], plan.paths_s.get("carry"))
            if grip.holding is False:
                out.status, out.reason = "failed", "the cube was lost on the way to its bin"
                self._grip(False)
                phase("empty", out)
                self._go_home(planner)
                return
            self._grip(False)
            phase("released", out)
            if "back" in paths:
                self._send_path(paths["back"], plan.paths_s.get("back"))
            out.status = "sorted"
            out.planned_motion_s = plan.duration_s
        except Exception as exc:
            out.status, out.reason = "failed", f"{type(exc).__name__}: {exc}"
            raise


def bin_color(cfg: SortConfig, color: str) -> str | None:
    """The colour of the bin a cube of `color` goes to (None: no bin for it)."""
    b = cfg.bin_for(color)
    return b.color if b is not None else None


def log_trajectory(log: RunLog, prefix: str, move: Move) -> None:
    """A planned move: what and how long (event), its TCP path in B (3D) and its end joints."""
    if not log.enabled:
        return
    log.event(f"{prefix}/moves", f"{move.kind} move: {move.what} ({move.traj.duration:.2f} s)")
    if len(move.tcp_path_B):
        log.lines3d(f"{prefix}/tcp_path_B", [move.tcp_path_B], color=(0, 160, 255))
    log.text(f"{prefix}/target_joints_deg", json.dumps(np.round(move.q_target, 3).tolist()))
