"""Sorting: capture, locate the cubes, plan and execute one pick-and-place per cube.

The pipeline talks to the cell only through the device interfaces (`drivers.base`: Camera,
LaserSwitch, Arm with its Gripper), so it runs the same on the simulated and the real cell.
Planning uses the core (`core.kinematics`, `core.motion`): inverse kinematics nearest the
current joints, a joint move to a pose above the cube, a straight descent, grasp, a straight
lift, a joint move over the bin of the cube's colour, release, and a joint move home. Every
move of a pick is planned and collision-checked (floor, target walls, camera boom, bins, the
other cubes, the gripper and the held cube) before the first move of that pick is sent.
Cubes that cannot be sorted (unknown colour, no bin, outside the workspace, unreachable, no
collision-free path) are reported with the reason and never approached. Motion is refused
unless the calibration is usable (present, intact, recent, robot registered).

Configuration: the `[sorting]` and `[registration]` sections of the cell file (see
`SortConfig` and `RegistrationConfig`); `[sorting] from_scene = true` takes bins, obstacles and
the gripper from the simulated cell's scene (simulated backend only).

The end of the file holds the simulation harness used by `omnisort sort` on the simulated
backend and by `omnisort evaluate sorting`: verification of the result from the simulator's
state, a collision monitor, and the random-scene experiment. That part reads the simulator's
truth; the pipeline itself never does.
"""

from __future__ import annotations

import itertools
import json
import math
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.extrinsics.common import SystemCalibration
from omnisort_hw.core.kinematics import URModel, forward, get_model, nearest_solution
from omnisort_hw.core.motion import (
    Box,
    Capsule,
    CollisionError,
    FloorPlane,
    MotionLimits,
    Trajectory,
    find_collision,
    plan_joint_move,
    plan_linear_move,
)
from omnisort_hw.core.objects import UNKNOWN, ColorTable, Cube, LocateSettings, locate_cubes
from omnisort_hw.core.registration import (
    Registration,
    invert,
    pose_from_offset,
    register_robot,
    tilt_prior_from_std,
)
from omnisort_hw.errors import (
    CalibrationFileError,
    ConfigError,
    InputError,
    MotionRefusedError,
)
from omnisort_hw.runlog import NullLog, RunLog

if TYPE_CHECKING:
    from drivers.base import Arm, Camera, LaserSwitch

JOINT_AT_TOLERANCE_DEG = 0.5
BLOCKED = "no collision-free path"


# ---- configuration --------------------------------------------------------------------------


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
class RegistrationConfig:
    """`[registration]`: the floor board and its pose in B (see `core.registration`)."""

    board: BoardSpec
    offset: tuple[float, float, float, float, float, float]
    fit: str = "auto"  # "auto" (tilt prior from the calibration's std), "level" or "free"
    camera_height_mm: float = 1200.0

    @property
    def T_B_board(self) -> np.ndarray:
        return pose_from_offset(self.offset)

    def tilt_prior(self, calib: SystemCalibration) -> float | None:
        """The board-tilt prior for `register_robot` (see `core.registration`)."""
        return tilt_prior(self.fit, calib)


FITS = ("auto", "level", "free")


def tilt_prior(fit: str, calib: SystemCalibration) -> float | None:
    """ "level" -> 0, "free" -> None, "auto" -> the calibration's camera roll/pitch 1-sigma."""
    if fit not in FITS:
        raise ConfigError(f"registration fit must be one of {', '.join(FITS)}, got {fit!r}")
    if fit == "level":
        return 0.0
    if fit == "free":
        return None
    return tilt_prior_from_std(calib.std)


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
    floor_z_B_mm: float = 0.0
    region_S_mm: tuple[float, float, float, float] | None = None
    workspace_B_mm: tuple[float, float, float, float] | None = None
    use_laser: bool = True
    bins: tuple[BinSpec, ...] = ()
    obstacles: tuple[ObstacleSpec, ...] = ()
    colors: ColorTable = field(default_factory=ColorTable.default)

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


def _floats(value: object, n: int | None, key: str) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or (n is not None and len(value) != n):
        raise ConfigError(f"{key}: expected a list of {n or 'some'} numbers, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ConfigError(f"{key}: expected finite numbers, got {value!r}")
        out.append(float(v))
    return tuple(out)


def _number(data: Mapping[str, Any], key: str, default: float, path: str, lo: float) -> float:
    v = data.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < lo:
        raise ConfigError(f"{path}.{key}: expected a number >= {lo}, got {v!r}")
    return float(v)


# `[sorting]` keys that are plain non-negative numbers, and every key the section knows.
_SORT_NUMBERS = (
    "tcp_offset_mm",
    "cube_size_mm",
    "gripper_stroke_mm",
    "grasp_above_center_mm",
    "approach_mm",
    "lift_mm",
    "release_clearance_mm",
    "joint_speed_deg_s",
    "joint_accel_deg_s2",
    "linear_speed_mm_s",
    "linear_accel_mm_s2",
    "collision_margin_mm",
    "max_sigma_mm",
)
_SORT_KEYS = {
    *_SORT_NUMBERS,
    "from_scene",
    "robot_model",
    "home_deg",
    "floor_z_B_mm",
    "region_S_mm",
    "workspace_B_mm",
    "use_laser",
    "bins",
    "obstacles",
    "colors",
    "colors_file",
}


def parse_sort_config(
    data: Mapping[str, Any], base: SortConfig | None = None, base_dir: Path | None = None
) -> SortConfig:
    """`[sorting]` -> SortConfig (on top of `base`); a wrong key names `[sorting].key`."""
    path = "[sorting]"
    unknown = sorted(set(data) - _SORT_KEYS)
    if unknown:
        raise ConfigError(
            f"{path}.{unknown[0]}: unknown key (known: {', '.join(sorted(_SORT_KEYS))})"
        )
    cfg = base or SortConfig()
    changes: dict[str, Any] = {}
    for key in _SORT_NUMBERS:
        if key in data:
            changes[key] = _number(data, key, 0.0, path, 0.0)
    if "floor_z_B_mm" in data:
        changes["floor_z_B_mm"] = _number(data, "floor_z_B_mm", 0.0, path, -1e4)
    if "robot_model" in data:
        name = str(data["robot_model"])
        try:
            get_model(name)
        except (KeyError, ValueError) as exc:
            raise ConfigError(f"{path}.robot_model: {exc}") from None
        changes["robot_model"] = name
    if "home_deg" in data:
        changes["home_deg"] = _floats(data["home_deg"], 6, f"{path}.home_deg")
    for key in ("region_S_mm", "workspace_B_mm"):
        if key in data:
            r = _floats(data[key], 4, f"{path}.{key}")
            if r[0] >= r[1] or r[2] >= r[3]:
                raise ConfigError(f"{path}.{key}: expected [xmin, xmax, ymin, ymax], got {r}")
            changes[key] = r
    if "use_laser" in data:
        if not isinstance(data["use_laser"], bool):
            raise ConfigError(f"{path}.use_laser: expected true or false")
        changes["use_laser"] = data["use_laser"]
    if "bins" in data:
        bins = []
        for i, b in enumerate(data["bins"]):
            key = f"{path}.bins[{i}]"
            if not isinstance(b, Mapping) or "color" not in b or "center_B_mm" not in b:
                raise ConfigError(f"{key}: needs color and center_B_mm")
            bins.append(
                BinSpec(
                    str(b["color"]),
                    _floats(b["center_B_mm"], 2, f"{key}.center_B_mm"),  # type: ignore[arg-type]
                    _floats(b.get("size_mm", [240.0, 240.0, 120.0]), 3, f"{key}.size_mm"),  # type: ignore[arg-type]
                    float(b.get("yaw_B_deg", 0.0)),
                )
            )
        changes["bins"] = tuple(bins)
    if "obstacles" in data:
        obs = []
        for i, o in enumerate(data["obstacles"]):
            key = f"{path}.obstacles[{i}]"
            if not isinstance(o, Mapping) or o.get("frame") not in ("S", "B"):
                raise ConfigError(f'{key}.frame: must be "S" or "B"')
            obs.append(
                ObstacleSpec(
                    str(o.get("name", f"obstacle {i}")),
                    str(o["frame"]),
                    _floats(o.get("center_mm"), 3, f"{key}.center_mm"),  # type: ignore[arg-type]
                    _floats(o.get("size_mm"), 3, f"{key}.size_mm"),  # type: ignore[arg-type]
                    float(o.get("yaw_deg", 0.0)),
                )
            )
        changes["obstacles"] = tuple(obs)
    if "colors" in data:
        changes["colors"] = ColorTable.from_mapping(data["colors"], f"{path}.colors")
    elif "colors_file" in data:
        p = Path(str(data["colors_file"]))
        if base_dir is not None and not p.is_absolute():
            p = base_dir / p
        changes["colors"] = ColorTable.load(p)
    return replace(cfg, **changes)


def parse_registration_config(data: Mapping[str, Any]) -> RegistrationConfig:
    """`[registration]`: board = "9x6", square_mm, offset = [X, Y, Z, RX, RY, RZ], fit."""
    path = "[registration]"
    known = {"board", "square_mm", "offset", "fit", "camera_height_mm"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown key (known: {', '.join(sorted(known))})")
    for key in ("square_mm", "offset"):
        if key not in data:
            raise ConfigError(f"{path}.{key}: missing")
    try:
        board = BoardSpec.parse(
            str(data.get("board", "9x6")), _number(data, "square_mm", 0, path, 0)
        )
    except ValueError as exc:
        raise ConfigError(f"{path}.board: {exc}") from None
    fit = data.get("fit", "auto")
    if fit not in FITS:
        raise ConfigError(f"{path}.fit: one of {', '.join(FITS)}, got {fit!r}")
    return RegistrationConfig(
        board,
        _floats(data["offset"], 6, f"{path}.offset"),  # type: ignore[arg-type]
        str(fit),
        _number(data, "camera_height_mm", 1200.0, path, 1.0),
    )


# ---- calibration sources ----------------------------------------------------------------------


class CalibrationSource:
    """Where the pipeline gets the system calibration, and the gate every motion passes."""

    def check_motion_allowed(self) -> None:
        raise NotImplementedError

    def system(self) -> SystemCalibration:
        raise NotImplementedError


class StoreCalibration(CalibrationSource):
    """The service's calibration store (checksums, age, camera serial)."""

    def __init__(self, store: Any) -> None:
        self.store = store

    def check_motion_allowed(self) -> None:
        self.store.check_motion_allowed()

    def system(self) -> SystemCalibration:
        rec = self.store.read("system")
        return SystemCalibration.from_json(rec.payload, source=str(rec.path))


class FileCalibration(CalibrationSource):
    """A system.json file (plain, or written by the store: then its checksum is verified); it
    must parse and be no older than `max_age_days` (from its save or creation time)."""

    def __init__(self, path: str | Path, max_age_days: float | None = None) -> None:
        self.path = Path(path)
        self.max_age_days = max_age_days

    def _payload(self) -> dict[str, Any]:
        if not self.path.is_file():
            raise CalibrationFileError(f"{self.path}: system calibration file not found")
        try:
            raw = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise CalibrationFileError(f"{self.path}: corrupt, not valid JSON ({exc})") from None
        if not isinstance(raw, dict):
            raise CalibrationFileError(f"{self.path}: corrupt, top level is not a JSON object")
        if "checksum" in raw:
            from omnisort_hw.storage import read_calibration_file

            rec = read_calibration_file(self.path, "system")
            payload = dict(rec.payload)
            payload["_saved"] = rec.saved.isoformat()
            return payload
        return raw

    def check_motion_allowed(self) -> None:
        try:
            payload = self._payload()
            SystemCalibration.from_json(payload, source=str(self.path))
        except CalibrationFileError as exc:
            raise MotionRefusedError(f"motion refused: calibration not usable: {exc}") from None
        if self.max_age_days is None:
            return
        stamp = payload.get("_saved") or payload.get("created")
        try:
            when = datetime.fromisoformat(str(stamp))
        except ValueError:
            raise MotionRefusedError(
                f"motion refused: {self.path}: no valid creation time ('created'), so its age "
                "cannot be checked"
            ) from None
        if when.tzinfo is None:
            when = when.replace(tzinfo=UTC)
        age = (datetime.now(UTC) - when).total_seconds() / 86400.0
        if age > self.max_age_days:
            raise MotionRefusedError(
                f"motion refused: {self.path} is {age:.1f} days old, older than "
                f"{self.max_age_days:g} days; recalibrate"
            )

    def system(self) -> SystemCalibration:
        payload = self._payload()
        payload.pop("_saved", None)
        return SystemCalibration.from_json(payload, source=str(self.path))


class MemoryCalibration(CalibrationSource):
    """A calibration held in memory (evaluation and tests); always usable."""

    def __init__(self, calib: SystemCalibration) -> None:
        self.calib = calib

    def check_motion_allowed(self) -> None:
        return None

    def system(self) -> SystemCalibration:
        return self.calib


def robot_base_T(calib: SystemCalibration, source: str = "system.json") -> np.ndarray:
    """T_SB from the calibration's `robot_base`, or MotionRefusedError if not registered."""
    rb = calib.robot_base
    if not isinstance(rb, Mapping) or "matrix" not in rb:
        raise MotionRefusedError(
            f"motion refused: {source} has no robot_base: register the robot first "
            "(omnisort register-robot, or the register_robot command)"
        )
    T = np.asarray(rb["matrix"], float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise MotionRefusedError(f"motion refused: {source}: robot_base.matrix is not a 4x4 pose")
    return T


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

    @property
    def moves(self) -> list[Move]:
        mid = [m for m in (self.descend, self.lift) if m is not None]
        return [*self.approach, *mid, *self.carry, *self.back]

    @property
    def duration_s(self) -> float:
        return float(sum(m.traj.duration for m in self.moves))


def _tool_pose(xyz: np.ndarray, yaw_deg: float) -> np.ndarray:
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
    return Box(tuple(pts.min(axis=0)), tuple(pts.max(axis=0)))  # type: ignore[arg-type]


class Planner:
    """Plans picks in B with the core's kinematics and motion, checking every move."""

    def __init__(
        self,
        cfg: SortConfig,
        T_SB: np.ndarray,
        joint_limits_deg: np.ndarray | None = None,
        workspace_check: Callable[[np.ndarray], None] | None = None,
    ) -> None:
        self.cfg = cfg
        self.T_SB = np.asarray(T_SB, float)
        self.T_BS = invert(self.T_SB)
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
        """A joint move, or when the straight joint path hits something, fold into the compact
        home posture, turn the base, and unfold (the arm sweeps a small circle meanwhile)."""
        try:
            return [self.plan_joint(q0, q1, obstacles, what, holding)]
        except CollisionError as direct:
            via = [self.fold(q0), self.fold(q1)]
            pts = [q0, *via, q1]
            moves = []
            try:
                for k, (a, b) in enumerate(itertools.pairwise(pts)):
                    if np.max(np.abs(a - b)) < 1e-6:
                        continue
                    step = ("fold", "turn", "unfold")[k]
                    moves.append(self.plan_joint(a, b, obstacles, f"{what} ({step})", holding))
            except CollisionError:
                raise direct from None
            return moves

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
        traj = plan_linear_move(self.model, q0, T, self.limits, tool=self.tool)
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

    def plan_pick(self, cube: Cube, others: Sequence[Cube], q_start: np.ndarray) -> PickPlan:
        """All moves of one pick from q_start back to home; `refused` says why not."""
        cfg = self.cfg
        bin_ = cfg.bin_for(cube.color)
        plan = PickPlan(cube, bin_)
        if cube.color == UNKNOWN:
            plan.refused = "unknown colour (matches no entry of the colour table)"
            return plan
        if bin_ is None:
            plan.refused = f"no bin configured for colour {cube.color!r}"
            return plan
        if not cube.sigma_mm <= cfg.max_sigma_mm:
            plan.refused = (
                f"location too uncertain ({cube.sigma_mm:.1f} mm > {cfg.max_sigma_mm:g} mm)"
            )
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
                self._pick_moves(plan, q_start, targets, yaw, bin_yaw, free, with_target)
            except MotionRefusedError as exc:
                errors.append(str(exc))
                continue
            plan.grasp_yaw_B_deg = _wrap180(yaw)
            return plan
        plan.approach, plan.descend, plan.lift, plan.carry, plan.back = [], None, None, [], []
        kind = (
            "no collision-free path" if all("come within" in e for e in errors) else "unreachable"
        )
        plan.refused = f"{kind}: {errors[0]}" if errors else kind
        return plan

    def _first_path(
        self,
        q0: np.ndarray,
        poses: Sequence[np.ndarray],
        obstacles: list[Box | FloorPlane],
        what: str,
    ) -> list[Move]:
        """The first collision-free joint path (holding the cube) to any of `poses`, trying
        for each the inverse kinematics nearest the start, the folded start and home."""
        last: MotionRefusedError | None = None
        for T in poses:
            tried: list[np.ndarray] = []
            for ref in (q0, self.fold(q0), self.home):
                try:
                    q1 = self.ik(T, ref)
                except MotionRefusedError as exc:
                    last = exc
                    continue
                if any(np.allclose(q1, t, atol=1e-6) for t in tried):
                    continue
                tried.append(q1)
                try:
                    return self.plan_joint_via(q0, q1, obstacles, what, holding=True)
                except MotionRefusedError as exc:
                    last = exc
        assert last is not None
        raise last

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
    ) -> None:
        T_app = _tool_pose(targets["approach"], yaw)
        T_grasp = _tool_pose(targets["grasp"], yaw)
        T_lift = _tool_pose(targets["lift"], yaw)
        q_app = self.ik(T_app, q_start)
        plan.approach = self.plan_joint_via(q_start, q_app, with_target, "move above the cube")
        plan.descend = self.plan_linear(q_app, T_grasp, free, "descend onto the cube")
        plan.lift = self.plan_linear(
            plan.descend.q_target, T_lift, free, "lift the cube", holding=True, held_on_floor=True
        )
        q_lift = plan.lift.q_target
        base = bin_yaw + 90.0 * round((yaw - bin_yaw) / 90.0)
        carry = self._first_path(
            q_lift,
            [_tool_pose(targets["release"], base + d) for d in (0.0, 90.0, -90.0, 180.0)],
            free,
            "carry the cube to its bin",
        )
        plan.carry = carry
        plan.back = self.plan_joint_via(plan.carry[-1].q_target, self.home, free, "return home")


def _translation(x: float, y: float, z: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _wrap180(deg: float) -> float:
    return float((deg + 180.0) % 360.0 - 180.0)


# ---- the pipeline ---------------------------------------------------------------------------


def _finite(value: float, digits: int) -> float | None:
    """A rounded number for JSON, None when it is not finite (strict JSON has no NaN)."""
    return round(float(value), digits) if math.isfinite(value) else None


@dataclass
class CubeOutcome:
    """What happened to one located cube."""

    index: int
    color: str
    center_S_mm: list[float]
    center_B_mm: list[float]
    yaw_B_deg: float
    sigma_mm: float
    status: str  # "sorted" (placed), "skipped" (refused before motion), "failed"
    reason: str = ""
    bin: str | None = None
    motion_s: float = 0.0
    error_mm: float | None = None  # filled by a verifier
    in_right_bin: bool | None = None  # filled by a verifier

    def to_dict(self) -> dict[str, Any]:
        out = {
            "index": self.index,
            "color": self.color,
            "center_S_mm": [_finite(v, 2) for v in self.center_S_mm],
            "center_B_mm": [_finite(v, 2) for v in self.center_B_mm],
            "yaw_B_deg": _finite(self.yaw_B_deg, 2),
            "sigma_mm": _finite(self.sigma_mm, 3),
            "status": self.status,
            "reason": self.reason,
            "bin": self.bin,
            "motion_s": round(self.motion_s, 3),
        }
        if self.error_mm is not None:
            out["error_mm"] = round(self.error_mm, 3)
        if self.in_right_bin is not None:
            out["in_right_bin"] = self.in_right_bin
        return out


@dataclass
class SortReport:
    """Per-cube outcomes and totals of one sorting run."""

    outcomes: list[CubeOutcome]
    registration: dict[str, Any] | None = None
    rejected_blobs: int = 0
    wall_s: float = 0.0
    verified: bool = False
    collisions: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def totals(self) -> dict[str, Any]:
        picked = [o for o in self.outcomes if o.status == "sorted"]
        out: dict[str, Any] = {
            "cubes": len(self.outcomes),
            "sorted": len(picked),
            "skipped": sum(o.status == "skipped" for o in self.outcomes),
            "failed": sum(o.status == "failed" for o in self.outcomes),
            "motion_s": round(sum(o.motion_s for o in self.outcomes), 3),
            "motion_s_per_pick": round(sum(o.motion_s for o in picked) / len(picked), 3)
            if picked
            else None,
            "wall_s": round(self.wall_s, 3),
        }
        if self.verified:
            out["sorted_ok"] = sum(bool(o.in_right_bin) for o in self.outcomes)
            errs = [o.error_mm for o in self.outcomes if o.error_mm is not None]
            out["mean_position_error_mm"] = round(float(np.mean(errs)), 3) if errs else None
            out["collisions"] = self.collisions
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "cubes": [o.to_dict() for o in self.outcomes],
            "totals": self.totals(),
            "registration": self.registration,
            "rejected_blobs": self.rejected_blobs,
            **self.extra,
        }


@dataclass
class Located:
    """The result of one capture + location: cubes and what was needed to find them."""

    cubes: list[Cube]
    T_SB: np.ndarray
    calib: SystemCalibration
    registration: Registration | None
    diagnostics: dict[str, Any]
    image: np.ndarray = field(repr=False)


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
    ) -> None:
        self.camera = camera
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

    # -- capture and location -------------------------------------------------------------

    def capture(self) -> tuple[np.ndarray, np.ndarray | None]:
        """A laser-off colour image and, with a laser switch and `use_laser`, a laser-on one."""
        laser_img = None
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
        from omnisort_hw.core.laser_stripe import laser_stripe_points
        from omnisort_hw.core.mapping import pixels_to_plane

        calib = calib or self.calibration.system()
        t0 = time.perf_counter()
        colour, laser_img = images if images is not None else self.capture()
        t1 = time.perf_counter()
        reg = None
        if register:
            if self.registration is None:
                raise ConfigError("[registration]: needed to register the robot from the image")
            rc = self.registration
            reg = register_robot(
                colour,
                calib.model,
                calib.R_SC,
                rc.board,
                rc.T_B_board,
                rc.tilt_prior(calib),
                rc.camera_height_mm,
            )
            log_registration(self.log, reg)
            T_SB = reg.T_SB
        else:
            T_SB = robot_base_T(calib)
        t2 = time.perf_counter()
        lp = None
        if laser_img is not None:
            px = laser_stripe_points(laser_img)
            lp = pixels_to_plane(px, calib)
            self.log.points2d("sorting/laser_image/stripe", px, color=(255, 0, 0), radius=1)
        exclude = board_exclusion(reg.record() if reg else calib.robot_base)
        settings = self.cfg.locate_settings(exclude)
        if settings.region_S_mm is None:
            settings = replace(settings, region_S_mm=default_region(calib.target))
        cubes, diag = locate_cubes(
            colour, calib.model, calib.R_SC, T_SB, self.cfg.colors, settings, lp
        )
        log_cubes(self.log, "sorting", cubes, diag)
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
        return Planner(self.cfg, T_SB, joint_lim, lim.check_position)

    def run(
        self,
        max_objects: int | None = None,
        colors: Sequence[str] | None = None,
        register: bool = False,
        verifier: SimVerifier | None = None,
    ) -> SortReport:
        """Sort every cube found (or `max_objects`, or only `colors`); returns the report."""
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
        if verifier is not None:
            verifier.snapshot()
        t_plan = time.perf_counter()
        planner = self._planner(loc.T_SB)
        outcomes: list[CubeOutcome] = []
        plans: list[PickPlan] = []
        for i, cube in enumerate(loc.cubes):
            others = [c for c in loc.cubes if c is not cube]
            if colors is not None and cube.color not in colors:
                plan = PickPlan(cube, self.cfg.bin_for(cube.color))
                plan.refused = f"colour {cube.color!r} not requested"
            else:
                plan = planner.plan_pick(cube, others, home)
            planner.commit(plan)
            plans.append(plan)
            outcomes.append(
                CubeOutcome(
                    i,
                    cube.color,
                    cube.center_S.tolist(),
                    cube.center_B.tolist(),
                    cube.yaw_B_deg,
                    cube.sigma_mm,
                    "skipped" if plan.refused else "planned",
                    plan.refused or "",
                    plan.bin.color if plan.bin else None,
                )
            )
            self.log.event(
                "sorting/plan",
                f"cube {i} ({cube.color}): "
                + (f"refused: {plan.refused}" if plan.refused else f"{plan.duration_s:.1f} s"),
                level="WARN" if plan.refused else "INFO",
            )
        # Pick what can be picked; then re-plan the cubes that only another cube blocked
        # (it may be gone now), until nothing changes. A re-plan is still a full plan made
        # before the first move towards that cube.
        t_exec = time.perf_counter()
        t_plan = t_exec - t_plan
        picked: set[int] = set()
        done = 0
        queue = [i for i, p in enumerate(plans) if p.refused is None]
        while True:
            for i in queue:
                plan, out = plans[i], outcomes[i]
                if max_objects is not None and done >= max_objects:
                    out.status, out.reason = "skipped", "max_objects reached"
                    continue
                if self.cancel.is_set():
                    out.status, out.reason = "skipped", "cancelled"
                    continue
                self._execute(plan, out, planner)
                done += 1
                if out.status == "sorted":
                    picked.add(i)
                if self.progress is not None:
                    self.progress({"cube": out.index, "status": out.status, "color": out.color})
            queue = []
            if not picked or (max_objects is not None and done >= max_objects):
                break
            for i, plan in enumerate(plans):
                if plan.refused is None or not plan.refused.startswith(BLOCKED):
                    continue
                if self.cancel.is_set():
                    break
                cube = loc.cubes[i]
                others = [c for k, c in enumerate(loc.cubes) if k != i and k not in picked]
                again = planner.plan_pick(cube, others, home)
                if again.refused is None:
                    planner.commit(again)
                    plans[i] = again
                    outcomes[i].status, outcomes[i].reason = "planned", ""
                    queue.append(i)
                    self.log.event("sorting/plan", f"cube {i} ({cube.color}): free now")
                    break
            if not queue:
                break
        report = SortReport(
            outcomes,
            registration=loc.registration.record() if loc.registration else None,
            rejected_blobs=len(loc.diagnostics.get("rejected", [])),
        )
        report.extra["timings_s"] = {
            **{k: round(v, 3) for k, v in loc.diagnostics.get("timings_s", {}).items()},
            "plan": round(t_plan, 3),
            "execute": round(time.perf_counter() - t_exec, 3),
        }
        if verifier is not None:
            verifier.verify(report, loc)
        report.wall_s = time.perf_counter() - t0
        return report

    def _go_home(self, planner: Planner) -> None:
        arm = self._require_arm()
        q = np.asarray(arm.joint_positions(), float)
        for move in planner.plan_joint_via(q, planner.home, planner.static, "move home"):
            self._send(move)

    def _send(self, move: Move) -> None:
        """Execute one planned move (the arm plans the same path again and checks its limits)."""
        arm = self._require_arm()
        if self.cancel.is_set():
            raise MotionRefusedError("sort cancelled")
        cur = np.asarray(arm.joint_positions(), float)
        if np.max(np.abs(cur - move.traj.q[0])) > JOINT_AT_TOLERANCE_DEG:
            raise MotionRefusedError(
                f"{move.what}: the arm is not where the plan starts (off by "
                f"{np.max(np.abs(cur - move.traj.q[0])):.2f} deg); nothing sent"
            )
        log_trajectory(self.log, "sorting/planned", move)
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
        tcp = np.asarray(arm.tcp_pose(), float)
        self.log.pose("sorting/executed/tcp", tcp)
        self._executed.append(tcp[:3, 3])
        self.log.points3d("sorting/executed/tcp_B", np.array(self._executed), radius=5.0)

    def _execute(self, plan: PickPlan, out: CubeOutcome, planner: Planner) -> None:
        """Run one planned pick; a grasp that holds nothing is reported and the arm goes home."""
        arm = self._require_arm()
        grip = arm.gripper
        assert plan.descend is not None and plan.lift is not None
        self.log.event("sorting/pick", f"cube {out.index} ({out.color}) -> bin {out.bin}")
        phase = self.on_pick or (lambda _phase, _out: None)
        try:
            grip.open()
            for move in [*plan.approach, plan.descend]:
                self._send(move)
            phase("grasping", out)
            grip.close()
            if grip.holding is False:
                out.status, out.reason = "failed", "the gripper closed on nothing"
                grip.open()
                phase("empty", out)
                self._send(plan.lift)
                self._go_home(planner)
                return
            phase("holding", out)
            for move in [plan.lift, *plan.carry]:
                self._send(move)
            if grip.holding is False:
                out.status, out.reason = "failed", "the cube was lost on the way to its bin"
                grip.open()
                phase("empty", out)
                self._go_home(planner)
                return
            grip.open()
            phase("released", out)
            for move in plan.back:
                self._send(move)
            out.status = "sorted"
            out.motion_s = plan.duration_s
        except Exception as exc:
            out.status, out.reason = "failed", f"{type(exc).__name__}: {exc}"
            raise


# ---- logging helpers ------------------------------------------------------------------------


def log_registration(log: RunLog, reg: Registration) -> None:
    """Board corners (image), board pose and T_SB (3D) of a registration."""
    log.points2d("registration/image/corners", reg.corners_px, color=(0, 200, 0), radius=2)
    log.points2d("registration/image/first_corner", reg.corners_px[:1], color=(255, 0, 0), radius=5)
    log.pose("registration/board_S", reg.T_S_board)
    log.pose("registration/T_SB", reg.T_SB)
    log.scalar("registration/rms_px", reg.rms_px)


def log_cubes(log: RunLog, prefix: str, cubes: Sequence[Cube], diag: Mapping[str, Any]) -> None:
    """Colour masks, blob outlines and cube centres of a location."""
    if not log.enabled:
        return
    masks = diag.get("masks", {})
    for name, m in masks.items():
        log.image(f"{prefix}/masks/{name}", m, bgr=False)
    strips = [c.outline_px for c in cubes if c.outline_px is not None]
    if strips:
        log.points2d(
            f"{prefix}/image/outlines", np.concatenate(strips), color=(255, 255, 0), radius=0.5
        )
    if cubes:
        log.points3d(f"{prefix}/cubes_S", np.array([c.center_S for c in cubes]), radius=20.0)
        log.points3d(f"{prefix}/cubes_B", np.array([c.center_B for c in cubes]), radius=20.0)
    log.text(f"{prefix}/cubes", json.dumps([c.summary() for c in cubes], indent=1))


def log_trajectory(log: RunLog, prefix: str, move: Move) -> None:
    """A planned move: what and how long (event), its TCP path in B (3D) and its end joints."""
    if not log.enabled:
        return
    log.event(f"{prefix}/moves", f"{move.kind} move: {move.what} ({move.traj.duration:.2f} s)")
    if len(move.tcp_path_B):
        log.lines3d(f"{prefix}/tcp_path_B", [move.tcp_path_B], color=(0, 160, 255))
    log.text(f"{prefix}/target_joints_deg", json.dumps(np.round(move.q_target, 3).tolist()))


# ---- helpers shared with the CLI and the service --------------------------------------------


def board_exclusion(
    robot_base: Mapping[str, Any] | None,
) -> list[tuple[float, float, float, float]]:
    """The floor board's area in S (objects there are the board's squares), if known."""
    if not isinstance(robot_base, Mapping) or "board_extent_S_mm" not in robot_base:
        return []
    ext = robot_base["board_extent_S_mm"]
    return [tuple(float(v) for v in ext)]  # type: ignore[list-item]


def default_region(target: Mapping[str, Any]) -> tuple[float, float, float, float] | None:
    """Between the target's walls (from the calibration's target record), 20 mm inside them."""
    left = target.get("wall_left_x_mm")
    right = target.get("wall_right_x_mm")
    if left is None or right is None:
        sep = target.get("separation_mm")
        centre = target.get("center_mm", [0.0, 0.0])
        if sep is None:
            return None
        left, right = centre[0] - sep / 2.0, centre[0] + sep / 2.0
    y0, y1 = -1e9, 1e9
    if "length_mm" in target and "center_mm" in target:
        y0 = target["center_mm"][1] - target["length_mm"] / 2.0
        y1 = target["center_mm"][1] + target["length_mm"] / 2.0
    return (float(left) + 20.0, float(right) - 20.0, float(y0), float(y1))


def write_robot_base(path: str | Path, record: Mapping[str, Any]) -> Path:
    """Put `robot_base` into a system.json (atomically, previous version kept).

    A file written by the calibration store (with a checksum) is re-saved through the store so
    its checksum stays valid; a plain file is rewritten as JSON.
    """
    from omnisort_hw import fileio

    p = Path(path)
    try:
        raw = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrationFileError(f"{p}: system calibration file not found") from None
    except (OSError, ValueError) as exc:
        raise CalibrationFileError(f"{p}: not a readable JSON system calibration ({exc})") from None
    if not isinstance(raw, dict):
        raise CalibrationFileError(f"{p}: top level is not a JSON object")
    if "checksum" in raw:
        from omnisort_hw.storage import CalibrationStore, read_calibration_file

        rec = read_calibration_file(p, "system")
        if p.name != "system.json":
            raise CalibrationFileError(f"{p}: a store file must be named system.json")
        payload = dict(rec.payload)
        payload["robot_base"] = dict(record)
        return CalibrationStore(state_dir=p.parent).save_system(payload, rec.camera_serial)
    raw["robot_base"] = dict(record)
    return fileio.atomic_write_json(p, raw, keep_history=True)


__all__ = [
    "BinSpec",
    "CalibrationSource",
    "CubeOutcome",
    "FileCalibration",
    "MemoryCalibration",
    "ObstacleSpec",
    "PickPlan",
    "Planner",
    "RegistrationConfig",
    "SortConfig",
    "SortReport",
    "Sorter",
    "StoreCalibration",
    "parse_registration_config",
    "parse_sort_config",
    "robot_base_T",
    "write_robot_base",
]


def configs_from_cell(
    doc: Mapping[str, Any], arm: Any, base_dir: Path | None = None
) -> tuple[SortConfig, RegistrationConfig | None]:
    """`[sorting]` and `[registration]` of a cell document; `[sorting] from_scene = true` takes
    bins, obstacles and the gripper from the simulated arm's scene (and the floor board, when
    there is no `[registration]`)."""
    if "sorting" not in doc:
        raise ConfigError(
            "[sorting]: missing; the sorting pipeline needs it (bins, obstacles, cube size, "
            "home pose; or from_scene = true on the simulated cell)"
        )
    section = dict(doc["sorting"])
    scene = None
    base = None
    if section.pop("from_scene", False):
        scene = getattr(getattr(arm, "cell", None), "scene", None)
        if scene is None:
            raise ConfigError("[sorting].from_scene: only with the simulated arm (backend = sim)")
        base = sim_sort_config(scene)
    cfg = parse_sort_config(section, base, base_dir)
    reg: RegistrationConfig | None = None
    if "registration" in doc:
        reg = parse_registration_config(doc["registration"])
    elif scene is not None:
        reg = sim_registration_config(scene)
    return cfg, reg


# ---- the service's pipeline commands (called by omnisort_hw.cell.Cell) ----------------------


class _CellCamera:
    """The cell's camera through the cell (its lock and its run log)."""

    def __init__(self, cell: Any) -> None:
        self.cell = cell

    def grab(self, timeout_s: float | None = None) -> Any:
        return self.cell.grab(timeout_s)


class _CellLaser:
    """The cell's laser switch through the cell (its lock and its status cache)."""

    def __init__(self, cell: Any) -> None:
        self.cell = cell

    def on(self) -> None:
        self.cell.set_laser(True)

    def off(self) -> None:
        self.cell.set_laser(False)


def _cell_image(cell: Any, image: str | None, laser: bool) -> np.ndarray:
    from omnisort_hw.extrinsics_pipeline import read_image

    if image is not None:
        return read_image(image)
    if cell.devices.laser is not None:
        cell.set_laser(laser)
    try:
        return np.asarray(cell.grab().image)
    finally:
        if laser and cell.devices.laser is not None:
            cell.set_laser(False)


def _need_section(cell: Any, name: str, what: str) -> Mapping[str, Any]:
    from omnisort_hw.cell import NotAvailableError

    section = cell.config.get(name)
    if not isinstance(section, Mapping):
        raise NotAvailableError(
            f"{what} needs a [{name}] section in the cell configuration"
            + (
                " (board, square_mm, offset = [X, Y, Z, RX, RY, RZ] of the board in B)"
                if name == "registration"
                else " (bins, obstacles, cube size, home pose; or from_scene = true)"
            )
        )
    return section


def service_register_robot(
    cell: Any, image: str | None, cancel: threading.Event | None = None
) -> dict[str, Any]:
    """`register_robot`: T_SB from the floor board in `image` (or a laser-off capture), saved
    as `robot_base` in the store's system.json."""
    rc = parse_registration_config(_need_section(cell, "registration", "the robot registration"))
    payload = dict(cell.store.load_system())
    calib = SystemCalibration.from_json(payload, source=str(cell.store.path("system")))
    img = _cell_image(cell, image, laser=False)
    if cancel is not None and cancel.is_set():
        raise MotionRefusedError("register_robot cancelled")
    reg = register_robot(
        img,
        calib.model,
        calib.R_SC,
        rc.board,
        rc.T_B_board,
        rc.tilt_prior(calib),
        rc.camera_height_mm,
    )
    log = cell.runlog
    log.image("registration/image", img)
    log_registration(log, reg)
    record = reg.record()
    record["offset"] = list(rc.offset)
    record["board"] = {
        "inner_corners": [rc.board.cols, rc.board.rows],
        "square_mm": rc.board.square_mm,
    }
    record["image"] = image or "capture"
    payload["robot_base"] = record
    path = cell.store.save_system(payload)
    return {"robot_base": record, "path": str(path)}


def service_locate(
    cell: Any, image: str | None, colors: list[str] | None, cancel: threading.Event | None = None
) -> dict[str, Any]:
    """`locate`: the cubes in `image` (or laser-off and laser-on captures), in S and B."""
    cfg, _ = configs_from_cell(
        {"sorting": _need_section(cell, "sorting", "the colour-blob location")},
        cell.devices.arm,
    )
    calib = SystemCalibration.from_json(
        cell.store.load_system(), source=str(cell.store.path("system"))
    )
    robot_base_T(calib, str(cell.store.path("system")))
    colour = _cell_image(cell, image, laser=False)
    laser_img = None
    if image is None and cfg.use_laser and cell.devices.laser is not None:
        laser_img = _cell_image(cell, None, laser=True)
    sorter = Sorter(_CellCamera(cell), None, None, MemoryCalibration(calib), cfg, log=cell.runlog)
    loc = sorter.locate(images=(colour, laser_img), calib=calib)
    cubes = [c.summary() for c in loc.cubes if colors is None or c.color in colors]
    return {"cubes": cubes, "count": len(cubes)}


def service_sort(
    cell: Any,
    max_objects: int | None,
    colors: list[str] | None,
    cancel: threading.Event | None = None,
    progress: Callable[[dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """`sort`: the whole pipeline on the cell's devices, gated by the calibration store."""
    doc = {"sorting": _need_section(cell, "sorting", "the sorting pipeline")}
    if isinstance(cell.config.get("registration"), Mapping):
        doc["registration"] = cell.config["registration"]
    cfg, reg = configs_from_cell(doc, cell.devices.arm)
    if cell.devices.camera is None or cell.devices.arm is None:
        raise MotionRefusedError("sort: the cell needs a camera and an arm")
    laser = _CellLaser(cell) if cell.devices.laser is not None else None
    sorter = Sorter(
        _CellCamera(cell),  # type: ignore[arg-type]
        cell.devices.arm,
        laser,  # type: ignore[arg-type]
        StoreCalibration(cell.store),
        cfg,
        reg,
        log=cell.runlog,
        cancel=cancel,
        progress=progress,
        on_pick=lambda phase, out: cell.journal.pick_phase(phase, out.index, out.color, out.bin),
    )
    from omnisort_hw.gripper_load import resolve_before_sort

    sorter.calibration.check_motion_allowed()
    held = resolve_before_sort(sorter, cell.journal, robot_base_T(sorter.calibration.system()))
    report = sorter.run(max_objects, colors)
    if held is not None:
        report.outcomes.insert(0, held)
    return report.to_dict()


# ---- simulation harness (verification and the random-scene experiment) ----------------------


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
        import pybullet as p

        names = self.world.info.names
        self._floor = next(b for b, n in names.items() if n == "floor")
        self._cubes = {body for _, body in self.world.info.cubes}
        self._links = p.getNumJoints(self.world.arm.body, physicsClientId=self.world.client)

    # -- truth ----------------------------------------------------------------------------

    def true_cubes(self) -> list[_TrueCube]:
        out = []
        with self.cell.lock:
            for i, (spec, body) in enumerate(self.world.info.cubes):
                T = self.world.body_pose(body)
                out.append(_TrueCube(i, spec.color.name, body, spec.size_mm, T[:3, 3].copy()))
        return out

    def snapshot(self) -> None:
        """Remember where the cubes are now (the truth the located positions compare with)."""
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

        self.world.step = step  # type: ignore[method-assign]

    def stop(self) -> None:
        if self._orig_step is not None:
            self.world.step = self._orig_step  # type: ignore[method-assign]
            self._orig_step = None

    def _check(self) -> None:
        import pybullet as p

        w = self.world
        cid = w.client
        arm_body = w.arm.body
        held = self.arm.gripper.held_body
        names = w.info.names
        floor = self._floor
        grip_xy = np.asarray(p.getLinkState(arm_body, 6, physicsClientId=cid)[4][:2]) / 1e-3
        nearest_cube, best = None, 60.0
        for body in self._cubes:
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
                if body in self._cubes and exempt:
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

    def verify(self, report: SortReport, loc: Located) -> None:
        """Fill each outcome's error against the truth and whether its cube is in the right bin;
        cubes the pipeline never found are added as "missed"."""
        truth = self.truth or self.true_cubes()
        final = {c.body: c.center_S for c in self.true_cubes()}
        T_BS_true = invert(self.T_SB())
        used: set[int] = set()
        for out in report.outcomes:
            c = np.asarray(out.center_S_mm)
            d = [
                np.linalg.norm(t.center_S[:2] - c[:2]) if t.index not in used else np.inf
                for t in truth
            ]
            if not d or min(d) > 60.0:
                continue
            t = truth[int(np.argmin(d))]
            used.add(t.index)
            out.error_mm = float(np.linalg.norm(t.center_S - c))
            true_B = T_BS_true[:3, :3] @ t.center_S + T_BS_true[:3, 3]
            report.extra.setdefault("errors_B_mm", []).append(
                float(np.linalg.norm(true_B - np.asarray(out.center_B_mm)))
            )
            out.in_right_bin = self.bin_of(final[t.body]) == t.color
        for t in truth:
            if t.index in used:
                continue
            in_bin = self.bin_of(final[t.body]) == t.color
            report.outcomes.append(
                CubeOutcome(
                    len(report.outcomes),
                    t.color,
                    t.center_S.tolist(),
                    [np.nan] * 3,
                    0.0,
                    float("nan"),
                    "missed",
                    "not located",
                    None,
                    in_right_bin=in_bin,
                )
            )
        report.verified = True
        report.collisions = len(self.collisions)
        report.extra["collision_events"] = list(self.collisions)


def sim_sort_config(scene: Any, base: SortConfig | None = None) -> SortConfig:
    """Bins, obstacles (walls, boom), gripper and region of a simulated scene, on top of `base`
    (simulated backend only: a real cell lists them in its `[sorting]` section)."""
    from sim_backend.scene import wall_footprints

    robot = scene.robot
    if robot is None:
        raise ConfigError(f"scene {scene.name!r} has no [robot]; cannot sort in it")
    cfg = base or SortConfig()
    yaw = math.radians(robot.base_yaw_deg)
    T_SB = np.eye(4)
    T_SB[:3, :3] = [
        [math.cos(yaw), -math.sin(yaw), 0],
        [math.sin(yaw), math.cos(yaw), 0],
        [0, 0, 1],
    ]
    T_SB[:3, 3] = (robot.base_mm[0], robot.base_mm[1], scene.floor_z + robot.pedestal_mm)
    T_BS = invert(T_SB)
    bins = []
    for b in scene.bins:
        c = T_BS[:3, :3] @ np.array([*b.position_mm, 0.0]) + T_BS[:3, 3]
        bins.append(
            BinSpec(
                b.color.name,
                (float(c[0]), float(c[1])),
                tuple(b.size_mm),  # type: ignore[arg-type]
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
    return RegistrationConfig(board, offset, "auto", scene.camera.height_mm)  # type: ignore[arg-type]


EVAL_COLORS = ("red", "green", "blue", "black")


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
    from sim_backend.scene import NAMED_COLORS, Color, CubeSpec
    from sim_backend.scene import BinSpec as SceneBin

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
    size = base.cubes[0].size_mm if base.cubes else 100.0
    cubes = tuple(
        CubeSpec(
            Color(c, NAMED_COLORS[c]),
            size,
            (float(p[0]), float(p[1])),
            float(rng.uniform(0.0, 90.0)),
        )
        for p, c in zip(placed, rng.choice(list(colors), n_cubes), strict=True)
    )
    bins = tuple(
        SceneBin(Color(c, NAMED_COLORS[c]), b.position_mm, b.size_mm, b.wall_mm, b.yaw_deg)
        for b, c in zip(base.bins, colors, strict=False)
    )
    ang = rng.uniform(-max_angle_deg, max_angle_deg, 3)
    robot_changes: dict[str, Any] = {}
    if home_deg is not None:
        robot_changes["home_deg"] = tuple(float(v) for v in home_deg)
    return base.replace(
        camera={"roll_deg": float(ang[0]), "pitch_deg": float(ang[1]), "yaw_deg": float(ang[2])},
        cubes=cubes,
        bins=bins,
        robot=robot_changes or {},
    )


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
    "wall_s_per_pick",
)


def evaluate_sorting(
    scenes: int = 50,
    seed: int = 0,
    width: int = 960,
    calibration: str = "truth",
    max_angle_deg: float = 10.0,
    cubes: tuple[int, int] = (3, 6),
    progress: Callable[[int, dict[str, Any]], None] | None = None,
    log: RunLog = NullLog,
) -> dict[str, Any]:
    """The random-scene experiment on the simulated cell: per scene, register the robot from the
    image, locate, sort, verify against the simulator's state; returns the totals.

    `calibration`: "truth" uses the true camera rotation and laser plane; "perturbed" adds the
    joint method's typical errors (0.1 deg per camera angle, 0.15 deg per laser angle, 3 mm
    laser distance, Gaussian) to emulate a calibrated cell.
    """
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch
    from sim_backend.scene import load_scene, sized

    if calibration not in ("truth", "perturbed"):
        raise InputError(f"--calibration must be truth or perturbed, got {calibration!r}")
    rng = np.random.default_rng(seed)
    base = sized(load_scene("sorting"), width)
    cfg0 = SortConfig()
    rows: list[dict[str, Any]] = []
    t_all = time.perf_counter()
    for k in range(scenes):
        n = int(rng.integers(cubes[0], cubes[1] + 1))
        scene = random_scene(base, rng, n, max_angle_deg=max_angle_deg, home_deg=cfg0.home_deg)
        cfg = sim_sort_config(scene, cfg0)
        reg_cfg = sim_registration_config(scene)
        cell = SimCell(scene, seed=seed * 1000 + k)
        cam, laser, arm = SimCamera(cell), SimLaserSwitch(cell), SimArm(cell)
        row: dict[str, Any] = {"scene": k, "cubes": n}
        try:
            for d in (cam, laser, arm):
                d.connect()
            truth = cam.grab(with_truth=True) and cam.last_truth
            assert truth is not None
            calib = SystemCalibration.from_json(truth, source="truth")
            if calibration == "perturbed":
                calib = perturb_calibration(calib, rng)
            verifier = SimVerifier(arm)
            verifier.start()
            sorter = Sorter(cam, arm, laser, MemoryCalibration(calib), cfg, reg_cfg, log)
            t0 = time.perf_counter()
            report = sorter.run(register=True, verifier=verifier)
            wall = time.perf_counter() - t0
            verifier.stop()
            from omnisort_hw.core.registration import pose_error

            assert report.registration is not None
            T_est = np.asarray(report.registration["matrix"], float)
            reg_mm, reg_deg = pose_error(T_est, verifier.T_SB())
            tot = report.totals()
            picks = max(1, tot["sorted"])
            row.update(
                sorted_ok=tot["sorted_ok"],
                collisions=tot["collisions"],
                position_errors_mm=[o.error_mm for o in report.outcomes if o.error_mm is not None],
                position_errors_B_mm=report.extra.get("errors_B_mm", []),
                registration_error_mm=reg_mm,
                registration_error_deg=reg_deg,
                motion_s_per_pick=tot["motion_s_per_pick"],
                wall_s_per_pick=wall / picks,
                skipped=[
                    o.reason for o in report.outcomes if o.status in ("skipped", "missed", "failed")
                ],
                collision_events=report.extra.get("collision_events", []),
                timings_s=report.extra.get("timings_s", {}),
            )
        except Exception as exc:
            row.update(sorted_ok=0, collisions=None, error=f"{type(exc).__name__}: {exc}")
        finally:
            for d in (arm, laser, cam):
                d.close()
            cell.close()
        rows.append(row)
        if progress is not None:
            progress(k, row)
    return summarize_sorting(rows, time.perf_counter() - t_all, seed, width, calibration)


def perturb_calibration(calib: SystemCalibration, rng: np.random.Generator) -> SystemCalibration:
    """The calibration with Gaussian errors of the joint method's typical size."""
    p = calib.parameters()
    sd = {
        "cam_roll_deg": 0.1,
        "cam_pitch_deg": 0.1,
        "cam_yaw_deg": 0.1,
        "laser_roll_deg": 0.15,
        "laser_pitch_deg": 0.15,
        "laser_distance_mm": 3.0,
    }
    noisy = {k: v + float(rng.normal(0.0, sd[k])) for k, v in p.items()}
    return SystemCalibration.from_angles(
        calib.model, noisy, "perturbed", target=calib.target, std=dict(sd)
    )


def summarize_sorting(
    rows: Sequence[dict[str, Any]], wall_s: float, seed: int, width: int, calibration: str
) -> dict[str, Any]:
    """Totals of the random-scene experiment (the keys `evaluate sorting --json` prints)."""
    cubes = int(sum(r["cubes"] for r in rows))
    ok = int(sum(r.get("sorted_ok", 0) for r in rows))
    coll = [r["collisions"] for r in rows if r.get("collisions") is not None]
    errs = [e for r in rows for e in r.get("position_errors_mm", [])]
    errs_b = [e for r in rows for e in r.get("position_errors_B_mm", [])]
    reg = [r["registration_error_mm"] for r in rows if "registration_error_mm" in r]
    reg_deg = [r["registration_error_deg"] for r in rows if "registration_error_deg" in r]
    per_pick = [r["motion_s_per_pick"] for r in rows if r.get("motion_s_per_pick")]
    wall_pick = [r["wall_s_per_pick"] for r in rows if "wall_s_per_pick" in r]

    def mean(v: Sequence[float]) -> float | None:
        return round(float(np.mean(v)), 4) if v else None

    stages = sorted({k for r in rows for k in r.get("timings_s", {})})
    timings = {
        k: mean([r["timings_s"][k] for r in rows if k in r.get("timings_s", {})]) for k in stages
    }

    def pmax(v: Sequence[float]) -> float | None:
        return round(float(np.max(v)), 4) if v else None

    return {
        "scenes": len(rows),
        "seed": seed,
        "width": width,
        "calibration": calibration,
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
        "motion_s_per_pick": mean(per_pick),
        "wall_s_per_pick": mean(wall_pick),
        "wall_s": round(wall_s, 1),
        "stage_wall_s_per_scene": timings,
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
