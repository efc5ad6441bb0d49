"""The simulated cell's side of a sorting run: its layout as `[sorting]`/`[registration]` would
give it, and verification of a run against the simulator's truth.

`SimVerifier` reads the simulator's state: where the cubes are, whether each ended in the bin
of its colour, and every contact of the arm or of a held cube with anything else (a monitor
hooked into the world's physics step). It joins a run through `Sorter.run`'s callbacks
(`on_located`, `on_done`); the sorting pipeline itself never reads the truth. `SimScene` is what
the device factory hands the pipeline as the cell's known scene (`[sorting] from_scene`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pybullet as p

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.frames import invert_pose
from omnisort_hw.core.pick_planning import BinSpec, ObstacleSpec, SortConfig
from omnisort_hw.errors import ConfigError
from sim_backend.scene import wall_footprints


@dataclass
class _TrueCube:
    index: int
    color: str
    body: int
    size_mm: float
    center_S: np.ndarray


class SimVerifier:
    """Reads the simulated cell's state: where the cubes are (truth), whether each ended in the
    bin of its colour, and every contact of the arm or of a held cube with anything else.

    A contact counts once when it starts (a pair of arm link and body that did not touch at
    the previous check). Exempt: the base and the first link on the floor they stand on, and
    the gripper's own contact with the cube it is picking (the cube nearest its axis).
    """

    GRIPPER_LINKS = (6, 7, 8)

    def __init__(self, arm: Any, check_every: int = 3) -> None:
        self.arm = arm
        self.cell = arm.cell
        self.world = self.cell.world
        self.check_every = max(1, int(check_every))
        self.truth: list[_TrueCube] = []
        self.collisions: list[str] = []
        self._touching: set[tuple[int, int]] = set()
        self._steps = 0
        self._orig_step: Callable[..., None] | None = None
        names = self.world.info.names
        self._floor = next(b for b, n in names.items() if n == "floor")
        self._links = p.getNumJoints(self.world.arm.body, physicsClientId=self.world.client)

    @property
    def _cubes(self) -> set[int]:
        """The cubes' bodies as they are now (the simulator's panel adds and removes cubes)."""
        return {body for _, body in self.world.info.cubes}

    # -- truth ----------------------------------------------------------------------------

    def true_cubes(self) -> list[_TrueCube]:
        out = []
        with self.cell.lock:
            for i, (spec, body) in enumerate(self.world.info.cubes):
                T = self.world.body_pose(body)
                out.append(_TrueCube(i, spec.color.name, body, spec.size_mm, T[:3, 3].copy()))
        return out

    def on_located(self, loc: Any = None) -> None:
        """Remember where the cubes are now (the truth the located positions compare with)."""
        del loc
        self.truth = self.true_cubes()

    def T_SB(self) -> np.ndarray:
        T = self.world.T_S_B
        assert T is not None
        return np.asarray(T, float)

    def bin_of(self, p_S: np.ndarray) -> str | None:
        """Colour of the bin whose inside holds point p (S), or None. A cube resting on cubes
        already in the bin counts as in it (its centre may be above the rim)."""
        fz = self.world.floor_z
        for b in self.cell.scene.bins:
            c, s = math.cos(math.radians(b.yaw_deg)), math.sin(math.radians(b.yaw_deg))
            d = p_S[:2] - np.asarray(b.position_mm)
            local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])
            inner = np.asarray(b.size_mm[:2]) / 2.0 - b.wall_mm
            if np.all(np.abs(local) <= inner) and fz <= p_S[2] <= fz + 3.0 * b.size_mm[2]:
                return b.color.name
        return None

    # -- contacts -------------------------------------------------------------------------

    def start(self) -> None:
        """Check contacts after every `check_every` physics steps from now on."""
        if self._orig_step is not None:
            return
        self._orig_step = self.world.step
        orig = self._orig_step

        def step(n: int = 1) -> None:
            orig(n)
            self._steps += 1
            if self._steps % self.check_every == 0:
                self._check()

        self.world.step = step

    def stop(self) -> None:
        if self._orig_step is not None:
            self.world.step = self._orig_step
            self._orig_step = None

    def _check(self) -> None:
        w = self.world
        cid = w.client
        arm_body = w.arm.body
        held = self.arm.gripper.held_body
        names = w.info.names
        floor = self._floor
        grip_xy = np.asarray(p.getLinkState(arm_body, 6, physicsClientId=cid)[4][:2]) / 1e-3
        nearest_cube, best = None, 60.0
        cubes = self._cubes
        for body in cubes:
            xy = np.asarray(p.getBasePositionAndOrientation(body, physicsClientId=cid)[0][:2])
            d = float(np.linalg.norm(xy / 1e-3 - grip_xy))
            if d < best:
                nearest_cube, best = body, d
        # Broad phase: bodies whose boxes overlap the arm's (and the held cube's) box.
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for link in range(-1, self._links):
            a, b = p.getAABB(arm_body, link, physicsClientId=cid)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        near = {o[0] for o in p.getOverlappingObjects(lo, hi, physicsClientId=cid) or ()}
        now: set[tuple[int, int]] = set()
        for body in near - {arm_body}:
            for c in p.getClosestPoints(arm_body, body, 0.0, physicsClientId=cid):
                link = int(c[3])
                if body == floor and link in (-1, 0):
                    continue
                exempt = body in (held, nearest_cube) and link in self.GRIPPER_LINKS
                if body in cubes and exempt:
                    continue
                now.add((link, body))
        if held is not None:
            a, b = p.getAABB(held, -1, physicsClientId=cid)
            for o in p.getOverlappingObjects(a, b, physicsClientId=cid) or ():
                body = o[0]
                if body in (arm_body, held, floor):
                    continue
                if p.getClosestPoints(held, body, 0.0, physicsClientId=cid):
                    now.add((-100, body))
        for link, body in sorted(now - self._touching):
            who = "held cube" if link == -100 else f"arm link {link}"
            self.collisions.append(f"{who} touched {names.get(body, body)}")
        self._touching = now

    # -- verification ---------------------------------------------------------------------

    def on_done(self, report: Any, loc: Any) -> None:
        """Fill each outcome's error against the truth and whether its cube is in the right bin;
        cubes the pipeline never found are added as "missed". `report` is the pipeline's
        `SortReport` (the simulator sits below the pipeline, so it is duck-typed here)."""
        del loc
        truth = self.truth or self.true_cubes()
        final = {c.body: c.center_S for c in self.true_cubes()}
        T_BS_true = invert_pose(self.T_SB())
        used: set[int] = set()
        for out in report.outcomes:
            c = np.asarray(out.center_S_mm)
            d = [
                float(np.linalg.norm(t.center_S[:2] - c[:2])) if t.index not in used else np.inf
                for t in truth
            ]
            if not d or min(d) > 60.0:
                continue
            t = truth[int(np.argmin(d))]
            used.add(t.index)
            out.error_mm = float(np.linalg.norm(t.center_S - c))
            true_B = T_BS_true[:3, :3] @ t.center_S + T_BS_true[:3, 3]
            errors = report.extra.errors_B_mm = report.extra.errors_B_mm or []
            errors.append(float(np.linalg.norm(true_B - np.asarray(out.center_B_mm))))
            out.in_right_bin = self.bin_of(final[t.body]) == t.color
        for t in truth:
            if t.index in used:
                continue
            in_bin = self.bin_of(final[t.body]) == t.color
            report.add_missed(t.color, t.center_S.tolist(), in_bin)
        report.verified = True
        report.collisions = len(self.collisions)
        report.extra.collision_events = list(self.collisions)


def scene_T_SB(scene: Any) -> np.ndarray:
    """The robot base B in S as the scene places it (yaw about Z, on its pedestal)."""
    robot = scene.robot
    yaw = math.radians(robot.base_yaw_deg)
    T_SB = np.eye(4)
    T_SB[:3, :3] = [
        [math.cos(yaw), -math.sin(yaw), 0],
        [math.sin(yaw), math.cos(yaw), 0],
        [0.0, 0.0, 1.0],
    ]
    T_SB[:3, 3] = (robot.base_mm[0], robot.base_mm[1], scene.floor_z + robot.pedestal_mm)
    return T_SB


def sim_sort_config(scene: Any, base: SortConfig | None = None) -> SortConfig:
    """Bins, obstacles (walls, boom), gripper and region of a simulated scene, on top of `base`
    (simulated backend only: a real cell lists them in its `[sorting]` section)."""
    robot = scene.robot
    if robot is None:
        raise ConfigError(f"scene {scene.name!r} has no [robot]; cannot sort in it")
    cfg = base or SortConfig()
    T_BS = invert_pose(scene_T_SB(scene))
    bins = []
    for b in scene.bins:
        c = T_BS[:3, :3] @ np.array([*b.position_mm, 0.0]) + T_BS[:3, 3]
        bins.append(
            BinSpec(
                b.color.name,
                (float(c[0]), float(c[1])),
                tuple(b.size_mm),
                b.yaw_deg - robot.base_yaw_deg,
            )
        )
    obstacles = []
    fz = scene.floor_z
    if scene.target is not None:
        t = scene.target
        for name, fp in wall_footprints(t):
            lo, hi = fp.min(axis=0), fp.max(axis=0)
            obstacles.append(
                ObstacleSpec(
                    f"target wall {name}",
                    "S",
                    (
                        float((lo[0] + hi[0]) / 2),
                        float((lo[1] + hi[1]) / 2),
                        fz + t.wall_height_mm / 2,
                    ),
                    (float(hi[0] - lo[0]), float(hi[1] - lo[1]), t.wall_height_mm),
                    0.0,
                )
            )
    if scene.boom.enabled:
        bm = scene.boom
        d = scene.laser.distance_mm
        r = bm.housing_radius_mm
        obstacles.append(
            ObstacleSpec("laser housing", "S", (0.0, 0.0, -d), (2 * r, 2 * r, bm.housing_height_mm))
        )
        obstacles.append(
            ObstacleSpec(
                "camera boom",
                "S",
                (0.0, -bm.rod_length_mm / 2.0, (-d + 40.0) / 2.0),
                (2 * bm.rod_radius_mm, bm.rod_length_mm, d + 40.0),
            )
        )
    size = scene.cubes[0].size_mm if scene.cubes else cfg.cube_size_mm
    region = None
    if scene.target is not None:
        t = scene.target
        half = t.separation_mm / 2.0
        region = (
            t.center_mm[0] - half + 20.0,
            t.center_mm[0] + half - 20.0,
            t.center_mm[1] - t.length_mm / 2.0,
            t.center_mm[1] + t.length_mm / 2.0,
        )
    return replace(
        cfg,
        robot_model=robot.model,
        tcp_offset_mm=robot.gripper.tcp_offset_mm,
        gripper_stroke_mm=robot.gripper.stroke_mm,
        cube_size_mm=size,
        floor_z_B_mm=-robot.pedestal_mm,
        bins=tuple(bins),
        obstacles=tuple(obstacles),
        region_S_mm=cfg.region_S_mm or region,
    )


def sim_registration_config(scene: Any) -> RegistrationConfig:
    """The floor board of a simulated scene as `[registration]` would give it."""
    robot = scene.robot
    if robot is None or robot.floor_board is None:
        raise ConfigError(f"scene {scene.name!r} has no [robot.floor_board]")
    fb = robot.floor_board
    offset = (
        fb.origin_base_mm[0],
        fb.origin_base_mm[1],
        fb.thickness_mm - robot.pedestal_mm,
        180.0,
        0.0,
        fb.yaw_base_deg,
    )
    board = BoardSpec(fb.inner_corners[0], fb.inner_corners[1], fb.square_mm)
    return RegistrationConfig(board, offset, "auto", scene.camera.height_mm)


class SimScene:
    """The simulated cell's scene for the sorting pipeline (`pipeline.sort.SceneLayout`)."""

    def __init__(self, cell: Any, arm: Any | None) -> None:
        self.cell = cell
        self.arm = arm

    def sort_config(self, base: SortConfig) -> SortConfig:
        return sim_sort_config(self.cell.scene, base)

    def registration_config(self) -> RegistrationConfig:
        return sim_registration_config(self.cell.scene)

    def verifier(self) -> SimVerifier:
        if self.arm is None:
            raise ConfigError("[arm]: the simulated cell has no arm to verify a sort with")
        return SimVerifier(self.arm)


def scene_of(devices: dict[str, Any]) -> SimScene | None:
    """The scene of the simulated devices made by `sim_backend.devices.open_devices`."""
    cell = next((d.cell for d in devices.values() if hasattr(d, "cell")), None)
    if cell is None:
        return None
    hosted = getattr(cell, "scene_layout", None)  # a cell in a child process (device_proxies)
    return hosted(devices.get("arm")) if hosted is not None else SimScene(cell, devices.get("arm"))
