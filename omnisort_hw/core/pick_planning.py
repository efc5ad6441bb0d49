"""Pick planning: every move of one pick-and-place, planned and collision-checked, in pure code.

Arrays in, plans out: no devices, no I/O. `Planner.plan_pick` plans the whole pick of one cube
with the core's kinematics and motion: inverse kinematics nearest the current joints, a joint
move to a pose above the cube, a straight descent, grasp, a straight lift, a joint move over the
bin of the cube's colour, release, and a joint move home. Every move is checked against the
floor, the configured obstacles (target walls, camera boom), the bins with what is in them,
the other cubes, the gripper and the held cube before the first move of the pick is sent.
Cubes that cannot be sorted (unknown colour, no bin, too uncertain, outside the workspace,
unreachable, no collision-free path) get `PickPlan.refused` with the reason and no moves.

`SortConfig` is the `[sorting]` section as the planner and the location use it (parsed and
validated by `omnisort_hw.config.sorting`); frames and units are those of docs/frames.md.

Over 600 lines: one planner; the moves of a pick and their collision checks share its state
(the held cube, the bins' contents, the other cubes) and change together.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from itertools import pairwise

import numpy as np

from omnisort_hw.core.collision import Box, Capsule, CollisionError, FloorPlane, find_collision
from omnisort_hw.core.cube_location import UNKNOWN, ColorTable, Cube, LocateSettings
from omnisort_hw.core.cube_uncertainty import capture_refusal
from omnisort_hw.core.frames import invert_pose
from omnisort_hw.core.kinematics import URModel, forward, get_model, nearest_solution
from omnisort_hw.core.motion import MotionLimits, Trajectory, plan_joint_move, plan_linear_move
from omnisort_hw.core.pick_blending import MoveChecks, blend_moves
from omnisort_hw.errors import MotionRefusedError

# A refusal that starts with this may clear once another cube has been picked.
BLOCKED = "no collision-free path"


# ---- the [sorting] record -------------------------------------------------------------------


@dataclass(frozen=True)
class BinSpec:
    """A bin for one colour: centre (x, y) in B, outer size (x, y, z) mm, yaw about B's z."""

    color: str
    center_B_mm: tuple[float, float]
    size_mm: tuple[float, float, float] = (240.0, 240.0, 120.0)
    yaw_B_deg: float = 0.0
    wall_mm: float = 10.0


@dataclass(frozen=True)
class ObstacleSpec:
    """A box obstacle: centre and size (mm) in frame "S" or "B", turned by yaw about Z."""

    name: str
    frame: str
    center_mm: tuple[float, float, float]
    size_mm: tuple[float, float, float]
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class SortConfig:
    """`[sorting]`: robot, gripper, heights, speeds, bins, obstacles, colours and regions.

    Heights are mm; `grasp_above_center_mm` puts the TCP that far above the cube's centre when
    the fingers close; `approach_mm` is the straight descent onto the grasp, `lift_mm` the
    straight lift after it; the cube is released with its bottom `release_clearance_mm` above
    the bin's rim. `region_S_mm` = [xmin, xmax, ymin, ymax] is where cubes are looked for;
    `workspace_B_mm` = [xmin, xmax, ymin, ymax] is where they may be picked. The gripper's
    collision envelope is two capsules across the finger axis sized from `tcp_offset_mm` and
    `gripper_stroke_mm` (the simulated parallel gripper's shape). In a cell file:

        [sorting]
        home_deg = [180, -70, -100, -100, 90, 90]   # compact, tool down, out of the view
        cube_size_mm = 100
        [[sorting.bins]]
        color = "red"
        center_B_mm = [-100, -420]
        size_mm = [240, 240, 120]
        [[sorting.obstacles]]
        name = "left wall"
        frame = "S"
        center_mm = [-557, 650, -700]
        size_mm = [30, 1085, 1000]
        [sorting.colors]
        red = [[0, 7, 110, 255, 50, 255], [168, 179, 110, 255, 50, 255]]

        [registration]
        board = "9x6"
        square_mm = 40
        offset = [200, -180, 2, 180, 0, 90]   # the board in B: mm, deg (Z-Y-X)
        fit = "auto"                          # or "level" / "free"
    """

    robot_model: str = "UR5e"
    tcp_offset_mm: float = 140.0
    home_deg: tuple[float, ...] = (180.0, -70.0, -100.0, -100.0, 90.0, 90.0)
    cube_size_mm: float = 100.0
    gripper_stroke_mm: float = 150.0
    grasp_above_center_mm: float = 8.0
    approach_mm: float = 150.0
    lift_mm: float = 200.0
    release_clearance_mm: float = 60.0
    joint_speed_deg_s: float = 120.0
    joint_accel_deg_s2: float = 240.0
    linear_speed_mm_s: float = 300.0
    linear_accel_mm_s2: float = 1200.0
    collision_margin_mm: float = 10.0
    max_sigma_mm: float = 5.0
    # How far off centre the open jaws still close on the cube (mm); None: half the stroke's
    # excess over the cube, (gripper_stroke_mm - cube_size_mm) / 2.
    capture_tolerance_mm: float | None = None
    floor_z_B_mm: float = 0.0
    region_S_mm: tuple[float, float, float, float] | None = None
    workspace_B_mm: tuple[float, float, float, float] | None = None
    use_laser: bool = True
    bins: tuple[BinSpec, ...] = ()
    obstacles: tuple[ObstacleSpec, ...] = ()
    colors: ColorTable = field(default_factory=ColorTable.default)

    def capture_tolerance(self) -> float:
        if self.capture_tolerance_mm is not None:
            return float(self.capture_tolerance_mm)
        return max(0.5 * (self.gripper_stroke_mm - self.cube_size_mm), 0.0)

    def bin_for(self, color: str) -> BinSpec | None:
        return next((b for b in self.bins if b.color == color), None)

    def locate_settings(
        self, exclude: Sequence[tuple[float, float, float, float]] = ()
    ) -> LocateSettings:
        return LocateSettings(
            cube_size_mm=self.cube_size_mm,
            region_S_mm=self.region_S_mm,
            exclude_S_mm=tuple(exclude),
            floor_z_B_mm=self.floor_z_B_mm,
        )


# ---- planning -------------------------------------------------------------------------------


@dataclass
class Move:
    """One planned move: joint or linear, its target and its trajectory (for checks and logs)."""

    kind: str
    what: str
    q_target: np.ndarray
    T_target: np.ndarray | None
    traj: Trajectory
    tcp_path_B: np.ndarray = field(default_factory=lambda: np.empty((0, 3)), repr=False)
    blend_mm: float = 0.0  # the arm passes within this of the target into the next move


@dataclass
class PickPlan:
    """The moves of one pick in phases (home -> above the cube -> grasp -> lift -> over the bin
    -> home), or why it is refused."""

    cube: Cube
    bin: BinSpec | None
    approach: list[Move] = field(default_factory=list)
    descend: Move | None = None
    lift: Move | None = None
    carry: list[Move] = field(default_factory=list)
    back: list[Move] = field(default_factory=list)
    refused: str | None = None
    grasp_yaw_B_deg: float = 0.0
    paths_s: dict[str, float] = field(default_factory=dict)

    @property
    def moves(self) -> list[Move]:
        mid = [m for m in (self.descend, self.lift) if m is not None]
        return [*self.approach, *mid, *self.carry, *self.back]

    @property
    def paths(self) -> dict[str, list[Move]]:
        """The blended paths of the pick: to the grasp, to the release, back home (each
        starts and ends at rest; the moves inside one blend by their `blend_mm`)."""
        reach = [*self.approach, *([self.descend] if self.descend is not None else [])]
        carry = [*([self.lift] if self.lift is not None else []), *self.carry]
        return {k: v for k, v in (("reach", reach), ("carry", carry), ("back", self.back)) if v}

    @property
    def duration_s(self) -> float:
        """The planned motion time: the blended paths' (or the moves' with stops)."""
        if self.paths_s:
            return float(sum(self.paths_s.values()))
        return float(sum(m.traj.duration for m in self.moves))

    @property
    def end_q(self) -> np.ndarray | None:
        """The joints the pick ends at (None when refused)."""
        moves = self.moves
        return moves[-1].q_target if moves else None


def tool_pose(xyz: np.ndarray, yaw_deg: float) -> np.ndarray:
    """TCP pose in B pointing straight down, fingers closing along (cos a+90, sin a+90)."""
    a = math.radians(yaw_deg)
    x = np.array([math.cos(a), math.sin(a), 0.0])
    z = np.array([0.0, 0.0, -1.0])
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    T[:3, 3] = xyz
    return T


def _aabb_B(T_BX: np.ndarray, center: np.ndarray, size: np.ndarray, yaw_deg: float) -> Box:
    """Axis-aligned box in B enclosing a box (centre/size/yaw about z) given in frame X."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * size / 2.0
    pts = (corners @ R.T + center) @ T_BX[:3, :3].T + T_BX[:3, 3]
    return Box(tuple(pts.min(axis=0)), tuple(pts.max(axis=0)))


class Planner:
    """Plans picks in B with the core's kinematics and motion, checking every move."""

    def __init__(
        self,
        cfg: SortConfig,
        T_SB: np.ndarray,
        joint_limits_deg: np.ndarray | None = None,
        workspace_check: Callable[[np.ndarray], object] | None = None,
        linear_joint_caps: tuple[float, float] | None = None,
    ) -> None:
        """`linear_joint_caps`: the joints' speed (deg/s) and acceleration (deg/s^2) a linear
        move may use, the arm's maxima (a UR's movel is limited by the tool's speed and
        acceleration and the joints' hardware limits only); default: the joint moves' limits."""
        self.cfg = cfg
        self.T_SB = np.asarray(T_SB, float)
        self.T_BS = invert_pose(self.T_SB)
        model = get_model(cfg.robot_model)
        if joint_limits_deg is not None:
            lim = np.asarray(joint_limits_deg, float)
            ml = model.limits
            model = model.with_limits(
                np.stack([np.maximum(ml[:, 0], lim[:, 0]), np.minimum(ml[:, 1], lim[:, 1])], 1)
            )
        self.model: URModel = model
        self.tool = np.eye(4)
        self.tool[2, 3] = cfg.tcp_offset_mm
        self.limits = MotionLimits(
            joint_speed_deg_s=cfg.joint_speed_deg_s,
            joint_acc_deg_s2=cfg.joint_accel_deg_s2,
            linear_speed_mm_s=cfg.linear_speed_mm_s,
            linear_acc_mm_s2=cfg.linear_accel_mm_s2,
        )
        self.linear_limits = self.limits
        if linear_joint_caps is not None:
            self.linear_limits = replace(
                self.limits,
                joint_speed_deg_s=float(linear_joint_caps[0]),
                joint_acc_deg_s2=float(linear_joint_caps[1]),
            )
        self.workspace_check = workspace_check
        self.home = np.asarray(cfg.home_deg, float)
        t = cfg.tcp_offset_mm
        stroke = cfg.gripper_stroke_mm
        self.gripper = (
            Capsule(
                6, (0.0, -stroke / 2.0, 0.42 * t), (0.0, stroke / 2.0, 0.42 * t), 38.0, "gripper"
            ),
            Capsule(
                6, (0.0, -stroke / 2.0, 0.86 * t), (0.0, stroke / 2.0, 0.86 * t), 32.0, "fingers"
            ),
        )
        hold = t + cfg.grasp_above_center_mm
        self.held = Capsule(
            6,
            (0.0, 0.0, hold),
            (0.0, 0.0, hold),
            cfg.cube_size_mm * math.sqrt(3) / 2.0,
            "held cube",
        )
        self.fixed: list[Box | FloorPlane] = [
            FloorPlane(np.array(_translation(0.0, 0.0, cfg.floor_z_B_mm)), "floor")
        ]
        for o in cfg.obstacles:
            T_BX = self.T_BS if o.frame == "S" else np.eye(4)
            box = _aabb_B(T_BX, np.asarray(o.center_mm), np.asarray(o.size_mm), o.yaw_deg)
            self.fixed.append(Box(box.lo_mm, box.hi_mm, o.name))
        self.bin_fill: dict[str, int] = {b.color: 0 for b in cfg.bins}

    def _per_layer(self, b: BinSpec) -> tuple[int, int]:
        """How many cubes fit side by side in a bin (along its x and y)."""
        size = self.cfg.cube_size_mm + 4.0
        inner = np.asarray(b.size_mm[:2]) - 2.0 * b.wall_mm
        nx, ny = (max(1, int(v // size)) for v in inner)
        return nx, ny

    def _bin_box(self, b: BinSpec) -> Box:
        """A bin as a solid box up to its rim, or up to the top of the cubes stacked in it."""
        sx, sy, sz = b.size_mm
        nx, ny = self._per_layer(b)
        layers = -(-self.bin_fill.get(b.color, 0) // (nx * ny))
        top = max(sz, b.wall_mm + layers * self.cfg.cube_size_mm)
        box = _aabb_B(
            np.eye(4),
            np.array([*b.center_B_mm, self.cfg.floor_z_B_mm + top / 2.0]),
            np.array([sx, sy, top]),
            b.yaw_B_deg,
        )
        return Box(box.lo_mm, box.hi_mm, f"bin {b.color}")

    @property
    def static(self) -> list[Box | FloorPlane]:
        """Floor, configured obstacles and the bins (with what has been put in them)."""
        return [*self.fixed, *(self._bin_box(b) for b in self.cfg.bins)]

    def release_point(self, b: BinSpec) -> tuple[np.ndarray, float]:
        """Where the next cube goes in bin b: the TCP position (B) and the tool yaw (deg) that
        puts the cube in the next free cell of the bin's grid, square to its walls."""
        nx, ny = self._per_layer(b)
        k = self.bin_fill.get(b.color, 0)
        layer, cell = divmod(k, nx * ny)
        ix, iy = cell % nx, cell // nx
        pitch = self.cfg.cube_size_mm + 4.0
        local = np.array([(ix - (nx - 1) / 2.0) * pitch, (iy - (ny - 1) / 2.0) * pitch])
        c, s = math.cos(math.radians(b.yaw_B_deg)), math.sin(math.radians(b.yaw_B_deg))
        xy = np.asarray(b.center_B_mm) + np.array(
            [c * local[0] - s * local[1], s * local[0] + c * local[1]]
        )
        floor = self.cfg.floor_z_B_mm
        stack_top = floor + b.wall_mm + layer * self.cfg.cube_size_mm
        bottom = max(floor + b.size_mm[2], stack_top) + self.cfg.release_clearance_mm
        z = bottom + self.cfg.cube_size_mm / 2.0 + self.cfg.grasp_above_center_mm
        return np.array([xy[0], xy[1], z]), b.yaw_B_deg

    def commit(self, plan: PickPlan) -> None:
        """Count a planned pick's cube into its bin (the next plan uses the next cell)."""
        if plan.refused is None and plan.bin is not None:
            self.bin_fill[plan.bin.color] = self.bin_fill.get(plan.bin.color, 0) + 1

    def cube_box(self, cube: Cube, name: str) -> Box:
        s = self.cfg.cube_size_mm
        box = _aabb_B(np.eye(4), cube.center_B, np.array([s, s, s]), cube.yaw_B_deg)
        return Box(box.lo_mm, box.hi_mm, name)

    def _check(
        self,
        traj: Trajectory,
        obstacles: Sequence[Box | FloorPlane],
        what: str,
        holding: bool = False,
        held_on_floor: bool = False,
    ) -> None:
        """Arm and gripper against every obstacle; a held cube against every obstacle but the
        floor when it still stands on it (the start of the lift)."""
        checks: list[tuple[tuple[Capsule, ...], Sequence[Box | FloorPlane]]] = [
            (self.gripper, obstacles)
        ]
        if holding:
            held_obs = (
                [o for o in obstacles if not isinstance(o, FloorPlane)]
                if held_on_floor
                else obstacles
            )
            checks.append(((self.held,), held_obs))
        for tools, obs in checks:
            hit = find_collision(
                self.model, traj.q, obs, tool_capsules=tools, margin_mm=self.cfg.collision_margin_mm
            )
            if hit is not None:
                raise CollisionError(
                    f"{what}: the {hit.link} would come within {self.cfg.collision_margin_mm:g} "
                    f"mm of {hit.obstacle!r}"
                )

    def tool_capsules(self, holding: bool) -> tuple[Capsule, ...]:
        """The gripper, and the held cube when holding."""
        return (*self.gripper, self.held) if holding else self.gripper

    def plan_joint(
        self,
        q0: np.ndarray,
        q1: np.ndarray,
        obstacles: Sequence[Box | FloorPlane],
        what: str,
        holding: bool = False,
    ) -> Move:
        """One joint move, collision-checked."""
        traj = plan_joint_move(q0, q1, self.limits, model=self.model)
        self._check(traj, obstacles, what, holding)
        return Move("joint", what, np.asarray(q1, float), None, traj, self._tcp_path(traj))

    def fold(self, q: np.ndarray) -> np.ndarray:
        """The home posture (compact, tool down) turned to q's base angle, keeping wrist 3."""
        return np.array([q[0], *self.home[1:5], q[5]])

    def plan_joint_via(
        self,
        q0: np.ndarray,
        q1: np.ndarray,
        obstacles: Sequence[Box | FloorPlane],
        what: str,
        holding: bool = False,
    ) -> list[Move]:
        """A joint move, or when the straight joint path hits something, the quickest
        collision-free way through the compact home posture (folded while the base turns, or
        folded first, or turned folded and unfolded last: the arm sweeps a small circle)."""
        try:
            return [self.plan_joint(q0, q1, obstacles, what, holding)]
        except CollisionError as direct:
            f0, f1 = self.fold(q0), self.fold(q1)
            # Folded on the way, at a quarter, half or three quarters of the base's turn.
            mid = [self.fold(q0 + k * (q1 - q0)) for k in (0.25, 0.5, 0.75)]
            routes = [*([q0, m, q1] for m in mid), [q0, f1, q1], [q0, f0, q1], [q0, f0, f1, q1]]
            routes.sort(key=lambda pts: sum(self._joint_time(a, b) for a, b in pairwise(pts)))
            for pts in routes:
                moves = []
                try:
                    for a, b in pairwise(pts):
                        if np.max(np.abs(a - b)) < 1e-6:
                            continue
                        step = "unfold" if b is q1 else ("fold" if a is q0 else "turn")
                        moves.append(self.plan_joint(a, b, obstacles, f"{what} ({step})", holding))
                except CollisionError:
                    continue
                return moves
            raise direct from None

    def _joint_time(self, q0: np.ndarray, q1: np.ndarray) -> float:
        """Duration of the trapezoidal joint move q0 -> q1 at the configured limits, s."""
        span = float(np.max(np.abs(np.asarray(q1) - np.asarray(q0))))
        v, a = self.cfg.joint_speed_deg_s, self.cfg.joint_accel_deg_s2
        if span * a <= v * v:
            return 2.0 * math.sqrt(span / a)
        return span / v + v / a

    def plan_linear(
        self,
        q0: np.ndarray,
        T: np.ndarray,
        obstacles: Sequence[Box | FloorPlane],
        what: str,
        holding: bool = False,
        held_on_floor: bool = False,
    ) -> Move:
        """One straight-line TCP move, collision-checked."""
        traj = plan_linear_move(self.model, q0, T, self.linear_limits, tool=self.tool)
        self._check(traj, obstacles, what, holding, held_on_floor)
        return Move("linear", what, traj.q[-1].copy(), T, traj, self._tcp_path(traj))

    def _tcp_path(self, traj: Trajectory, samples: int = 40) -> np.ndarray:
        """The TCP's path in B (for the run log), at most `samples` points."""
        idx = np.unique(np.linspace(0, len(traj) - 1, min(samples, len(traj))).astype(int))
        return forward(self.model, traj.q[idx], self.tool)[:, :3, 3]

    def ik(self, T: np.ndarray, q_near: np.ndarray) -> np.ndarray:
        return nearest_solution(
            self.model, T, q_near, tool=self.tool, allow_singular=False, singular_tol=0.02
        )

    def plan_pick(
        self, cube: Cube, others: Sequence[Cube], q_start: np.ndarray, end_home: bool = True
    ) -> PickPlan:
        """All moves of one pick from q_start back to home (or, with `end_home` False, ending
        over the bin where the cube is released: the next pick starts there); `refused` says
        why not."""
        cfg = self.cfg
        bin_ = cfg.bin_for(cube.color)
        plan = PickPlan(cube, bin_)
        if cube.color == UNKNOWN:
            plan.refused = "unknown colour (matches no entry of the colour table)"
            return plan
        if bin_ is None:
            plan.refused = f"no bin configured for colour {cube.color!r}"
            return plan
        fit_sigma = float(np.hypot(*cube.sigma_xy_mm))  # the outline fit's own: its quality
        if not fit_sigma <= cfg.max_sigma_mm:
            plan.refused = f"location too uncertain ({fit_sigma:.1f} mm > {cfg.max_sigma_mm:g} mm)"
            return plan
        uncertain = capture_refusal(cube, cfg.capture_tolerance())
        if uncertain is not None:
            plan.refused = uncertain
            return plan
        c = cube.center_B
        if cfg.workspace_B_mm is not None:
            x0, x1, y0, y1 = cfg.workspace_B_mm
            if not (x0 <= c[0] <= x1 and y0 <= c[1] <= y1):
                plan.refused = (
                    f"outside the workspace: centre ({c[0]:.0f}, {c[1]:.0f}) mm in B is not in "
                    f"x [{x0:g}, {x1:g}], y [{y0:g}, {y1:g}]"
                )
                return plan
        grasp_z = c[2] + cfg.grasp_above_center_mm
        targets = {
            "grasp": np.array([c[0], c[1], grasp_z]),
            "approach": np.array([c[0], c[1], grasp_z + cfg.approach_mm]),
            "lift": np.array([c[0], c[1], grasp_z + cfg.lift_mm]),
        }
        targets["release"], bin_yaw = self.release_point(bin_)
        if self.workspace_check is not None:
            for name, p in targets.items():
                try:
                    self.workspace_check(p)
                except Exception as exc:
                    plan.refused = f"outside the workspace ({name} point): {exc}"
                    return plan
        all_cubes = [
            self.cube_box(o, f"{o.color} cube at {np.round(o.center_B[:2]).tolist()}")
            for o in others
        ]
        target_box = self.cube_box(cube, "the cube being picked")
        free = [*self.static, *all_cubes]
        with_target = [*free, target_box]
        errors: list[str] = []
        wrist = self._wrist_yaw(q_start)
        for k in sorted(range(4), key=lambda k: abs(_wrap180(cube.yaw_B_deg + 90.0 * k - wrist))):
            yaw = cube.yaw_B_deg + 90.0 * k
            try:
                self._pick_moves(plan, q_start, targets, yaw, bin_yaw, free, with_target, end_home)
            except MotionRefusedError as exc:
                errors.append(str(exc))
                continue
            plan.grasp_yaw_B_deg = _wrap180(yaw)
            self._blend(plan, q_start, free, with_target)
            return plan
        plan.approach, plan.descend, plan.lift, plan.carry, plan.back = [], None, None, [], []
        kind = (
            "no collision-free path" if all("come within" in e for e in errors) else "unreachable"
        )
        plan.refused = f"{kind}: {errors[0]}" if errors else kind
        return plan

    def _blend(
        self,
        plan: PickPlan,
        q_start: np.ndarray,
        free: list[Box | FloorPlane],
        with_target: list[Box | FloorPlane],
    ) -> None:
        """Blend radii of the pick's paths from the clearance, and their blended durations
        (see `core.pick_blending`)."""
        assert plan.descend is not None and plan.lift is not None
        reach = [MoveChecks(with_target)] * len(plan.approach) + [MoveChecks(free)]
        carry = [MoveChecks(free, True)] * (1 + len(plan.carry))
        checks = {"reach": reach, "carry": carry, "back": [MoveChecks(free)] * len(plan.back)}
        q0 = q_start
        for name, moves in plan.paths.items():
            try:
                blended = blend_moves(self, q0, moves, checks[name])
            except MotionRefusedError:  # not blendable: the checked moves, with stops
                blended = None
            for k, m in enumerate(moves):
                m.blend_mm = blended.blends_mm[k] if blended is not None else 0.0
            plan.paths_s[name] = (
                blended.duration_s
                if blended is not None
                else float(sum(m.traj.duration for m in moves))
            )
            q0 = moves[-1].q_target

    def path_to_any(
        self,
        q0: np.ndarray,
        poses: Sequence[np.ndarray],
        obstacles: Sequence[Box | FloorPlane],
        what: str,
        holding: bool = True,
    ) -> list[Move]:
        """A collision-free joint path (holding the cube by default) to any of `poses`, the
        quickest inverse kinematics goal first (see `_ik_goals`)."""
        last: MotionRefusedError | None = None
        for q1 in self._ik_goals(q0, poses):
            try:
                return self.plan_joint_via(q0, q1, obstacles, what, holding=holding)
            except MotionRefusedError as exc:
                last = exc
        assert last is not None
        raise last

    def _ik_goals(self, q0: np.ndarray, poses: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Distinct inverse kinematics of `poses` nearest the start, the folded start and
        home, quickest straight joint move from q0 first (a lower bound of any route's time)."""
        goals: list[np.ndarray] = []
        last: MotionRefusedError | None = None
        for T in poses:
            for ref in (q0, self.fold(q0), self.home):
                try:
                    q1 = self.ik(T, ref)
                except MotionRefusedError as exc:
                    last = exc
                    continue
                if not any(np.allclose(q1, g, atol=1e-6) for g in goals):
                    goals.append(q1)
        if not goals:
            assert last is not None
            raise last
        return sorted(goals, key=lambda g: self._joint_time(q0, g))

    def _wrist_yaw(self, q: np.ndarray) -> float:
        T = forward(self.model, np.asarray(q, float), self.tool)
        return math.degrees(math.atan2(T[1, 0], T[0, 0]))

    def _pick_moves(
        self,
        plan: PickPlan,
        q_start: np.ndarray,
        targets: dict[str, np.ndarray],
        yaw: float,
        bin_yaw: float,
        free: list[Box | FloorPlane],
        with_target: list[Box | FloorPlane],
        end_home: bool = True,
    ) -> None:
        T_app = tool_pose(targets["approach"], yaw)
        T_grasp = tool_pose(targets["grasp"], yaw)
        T_lift = tool_pose(targets["lift"], yaw)
        last: MotionRefusedError | None = None
        for q_app in self._ik_goals(q_start, [T_app]):
            try:
                plan.approach = self.plan_joint_via(
                    q_start, q_app, with_target, "move above the cube"
                )
                plan.descend = self.plan_linear(q_app, T_grasp, free, "descend onto the cube")
                plan.lift = self.plan_linear(
                    plan.descend.q_target,
                    T_lift,
                    free,
                    "lift the cube",
                    holding=True,
                    held_on_floor=True,
                )
                break  # an arm branch that reaches down to the cube and back up
            except MotionRefusedError as exc:
                last = exc
        else:
            assert last is not None
            raise last
        q_lift = plan.lift.q_target
        base = bin_yaw + 90.0 * round((yaw - bin_yaw) / 90.0)
        releases = [tool_pose(targets["release"], base + d) for d in (0.0, 90.0, -90.0, 180.0)]
        plan.carry = self.path_to_any(q_lift, releases, free, "carry the cube to its bin")
        if end_home:
            plan.back = self.plan_joint_via(plan.carry[-1].q_target, self.home, free, "return home")


def _translation(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _wrap180(deg: float) -> float:
    return float((deg + 180.0) % 360.0 - 180.0)
