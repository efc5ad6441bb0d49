"""One pybullet world (DIRECT) built from a `Scene`, in S with metres inside pybullet.

Besides the bodies, the world keeps what the renderer and the truth need and pybullet does not
know: the analytic patterned faces (`Panel`: target wall faces, checkerboard fronts), the
floor pattern, named planar faces for the exact laser polylines, and the target's markers.
The floor is collision-only (the renderer shades it analytically), so it costs no raster time.

Over 600 lines: the bodies and the analytic records the renderer and the truth read (panels,
markers, boards) are one description of the scene; split, each half would import the other.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import TypedDict

import numpy as np
import pybullet as p
from scipy.spatial.transform import Rotation

from omnisort_hw.core.frames import camera_rotation, homogeneous, laser_normal, rot_z
from sim_backend.geometry import Rect, box_faces
from sim_backend.patterns import CheckerPattern, FloorPattern, Marker, WallPattern
from sim_backend.robot import ArmBodies, build_arm, tcp_pose, ur_model
from sim_backend.scene import BinSpec, BoardSpec, CubeSpec, Scene, TargetSpec

MM = 1e-3
FLOOR_HALF_M = 20.0


@dataclass(frozen=True)
class Panel:
    """A patterned planar face of a body, shaded analytically by the renderer."""

    body: int
    rect: Rect
    pattern: WallPattern | CheckerPattern


@dataclass(frozen=True)
class AnalyticBox:
    """A box body shaded analytically (exact ray/box hits): pose in S (mm), uniform colour."""

    name: str
    body: int
    center: np.ndarray
    R: np.ndarray
    half: np.ndarray
    color: tuple[float, float, float]
    dynamic: bool = False


@dataclass(frozen=True)
class AnalyticCylinder:
    """A static capped cylinder (the boom's emitter housing and rod), shaded analytically:
    axis from `p0` to `p1` in S (mm), radius (mm), uniform colour."""

    name: str
    body: int
    p0: np.ndarray
    p1: np.ndarray
    radius: float
    color: tuple[float, float, float]


@dataclass(frozen=True)
class MarkerTruth:
    """A target marker: wall, name, paper letter (A-D at the border ends, else ''), corners in S."""

    wall: str
    name: str
    letter: str
    center: np.ndarray
    corners: np.ndarray


@dataclass(frozen=True)
class BoardTruth:
    """A checkerboard's pose and inner corners in S (row by row)."""

    name: str
    inner_corners: tuple[int, int]
    square_mm: float
    corners: np.ndarray
    pose: np.ndarray
    rect: Rect
    body: int
    on_floor: bool = False


class WallTruth(TypedDict):
    """One wall of the target in S (mm; unit vectors along the wall and along its normal)."""

    name: str
    inner_face_origin_mm: np.ndarray
    along_wall: np.ndarray
    normal: np.ndarray
    length_mm: float
    border_segment_S_mm: list[np.ndarray]


@dataclass
class WorldInfo:
    """What the renderer and the truth need besides pybullet's bodies."""

    panels: dict[int, Panel] = field(default_factory=dict)
    names: dict[int, str] = field(default_factory=dict)
    static_rects: list[tuple[str, int, Rect]] = field(default_factory=list)
    markers: list[MarkerTruth] = field(default_factory=list)
    boards: list[BoardTruth] = field(default_factory=list)
    walls: list[WallTruth] = field(default_factory=list)
    cubes: list[tuple[CubeSpec, int]] = field(default_factory=list)
    boxes: list[AnalyticBox] = field(default_factory=list)
    cylinders: list[AnalyticCylinder] = field(default_factory=list)
    no_laser: set[int] = field(default_factory=set)


def _quat(R: np.ndarray) -> list[float]:
    return list(Rotation.from_matrix(R).as_quat())


class SimWorld:
    """The pybullet world of one scene. Not thread-safe: `SimCell` serialises access."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.client = p.connect(p.DIRECT)
        p.resetSimulation(physicsClientId=self.client)
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=self.client)
        p.setTimeStep(1.0 / 240.0, physicsClientId=self.client)
        self.time_step = 1.0 / 240.0
        self.sim_time = 0.0
        self.version = 0
        self.info = WorldInfo()
        self.floor_z = scene.floor_z
        self.R_SC = camera_rotation(
            *np.radians([scene.camera.roll_deg, scene.camera.pitch_deg, scene.camera.yaw_deg])
        )
        self.laser_angles_deg = (scene.laser.roll_deg, scene.laser.pitch_deg)
        self.laser_normal = laser_normal(*np.radians(self.laser_angles_deg))
        self.laser_distance = scene.laser.distance_mm
        self.laser_on = scene.laser.on
        self.floor = FloorPattern(
            self.floor_z,
            scene.floor.work_area_mm,
            scene.floor.color.rgb,
            scene.floor.work_area_color.rgb,
        )
        self.arm: ArmBodies | None = None
        # Per camera configuration: the exact static hits of the pixel centres (render.py).
        self.render_cache: dict[str, object] = {}
        self.T_S_B: np.ndarray | None = None
        self._build()

    # ---- construction -----------------------------------------------------------------

    def _box(
        self,
        name: str,
        center_mm: np.ndarray,
        R: np.ndarray,
        half_mm: np.ndarray,
        rgb: tuple[float, float, float],
        mass: float = 0.0,
        collision: bool = True,
        visual: bool = True,
        analytic: bool = True,
    ) -> int:
        half = [float(h) * MM for h in half_mm]
        col = (
            p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=self.client)
            if collision
            else -1
        )
        # A body without a visual shape would be drawn from its collision shape: give hidden
        # bodies a speck of a visual far below the floor instead.
        vis = p.createVisualShape(
            p.GEOM_BOX,
            halfExtents=half if visual else [1e-5] * 3,
            rgbaColor=[*rgb, 1.0],
            visualFramePosition=[0.0, 0.0, 0.0] if visual else [0.0, 0.0, -100.0],
            physicsClientId=self.client,
        )
        body = p.createMultiBody(
            baseMass=mass,
            baseCollisionShapeIndex=col,
            baseVisualShapeIndex=vis,
            basePosition=list(np.asarray(center_mm, float) * MM),
            baseOrientation=_quat(R),
            physicsClientId=self.client,
        )
        self.info.names[body] = name
        if analytic and visual:
            self.info.boxes.append(
                AnalyticBox(
                    name,
                    body,
                    np.asarray(center_mm, float),
                    np.asarray(R, float),
                    np.asarray(half_mm, float),
                    rgb,
                    dynamic=mass > 0.0,
                )
            )
        return body

    def _build(self) -> None:
        s = self.scene
        floor = self._box(
            "floor",
            np.array([0.0, 0.0, self.floor_z - 50.0]),
            np.eye(3),
            np.array([FLOOR_HALF_M * 1000.0, FLOOR_HALF_M * 1000.0, 50.0]),
            s.floor.color.rgb,
            visual=False,
            analytic=False,
        )
        p.changeDynamics(floor, -1, lateralFriction=0.8, physicsClientId=self.client)
        self.floor_body = floor
        half = FLOOR_HALF_M * 1000.0
        self.info.static_rects.append(
            (
                "floor",
                floor,
                Rect(
                    "floor",
                    np.array([-half, -half, self.floor_z]),
                    np.array([1.0, 0.0, 0.0]),
                    np.array([0.0, 1.0, 0.0]),
                    2 * half,
                    2 * half,
                    np.array([0.0, 0.0, 1.0]),
                ),
            )
        )
        if s.boom.enabled:
            self._build_boom()
        self._target_bodies: set[int] = set()
        self.target_spec: TargetSpec | None = None  # as it stands now (None: taken away)
        if s.target is not None:
            self.set_target(s.target)
        for board in s.checkerboards:
            self._build_board(board)
        for i, cube in enumerate(s.cubes):
            self._build_cube(i, cube)
        for i, b in enumerate(s.bins):
            self._build_bin(i, b)
        if s.robot is not None:
            self._build_robot()

    def _build_boom(self) -> None:
        b = self.scene.boom
        d = self.scene.laser.distance_mm
        rgba = [*b.color.rgb, 1.0]
        vis = p.createVisualShape(
            p.GEOM_CYLINDER,
            radius=b.housing_radius_mm * MM,
            length=b.housing_height_mm * MM,
            rgbaColor=rgba,
            physicsClientId=self.client,
        )
        housing = p.createMultiBody(
            0.0, -1, vis, basePosition=[0.0, 0.0, -d * MM], physicsClientId=self.client
        )
        self.info.names[housing] = "laser_housing"
        self.info.no_laser.add(housing)
        self.info.cylinders.append(
            AnalyticCylinder(
                "laser_housing",
                housing,
                np.array([0.0, 0.0, -d - b.housing_height_mm / 2.0]),
                np.array([0.0, 0.0, -d + b.housing_height_mm / 2.0]),
                b.housing_radius_mm,
                b.color.rgb,
            )
        )
        # The rod climbs from the housing's side to the boom behind the camera (towards -Y).
        start = np.array([0.0, -b.housing_radius_mm * 0.6, -d + b.housing_height_mm / 2.0])
        end = np.array([0.0, -b.rod_length_mm, 40.0])
        axis = end - start
        length = float(np.linalg.norm(axis))
        z = axis / length
        x = np.array([1.0, 0.0, 0.0])
        R = np.stack([x, np.cross(z, x), z], axis=1)
        centre = (start + end) / 2.0
        rod_vis = p.createVisualShape(
            p.GEOM_CYLINDER,
            radius=b.rod_radius_mm * MM,
            length=length * MM,
            rgbaColor=rgba,
            physicsClientId=self.client,
        )
        rod_col = p.createCollisionShape(
            p.GEOM_CYLINDER,
            radius=b.rod_radius_mm * MM,
            height=length * MM,
            physicsClientId=self.client,
        )
        rod = p.createMultiBody(
            0.0,
            rod_col,
            rod_vis,
            basePosition=list(centre * MM),
            baseOrientation=_quat(R),
            physicsClientId=self.client,
        )
        self.info.names[rod] = "boom_rod"
        self.info.cylinders.append(
            AnalyticCylinder("boom_rod", rod, start, end, b.rod_radius_mm, b.color.rgb)
        )

    def set_target(self, t: TargetSpec | None) -> None:
        """Take the target away and, with `t`, build `t` in its place (the simulator's panel
        sets its kind and pose); the renderer's cached static geometry is dropped."""
        info = self.info
        self._remove_bodies(self._target_bodies)
        info.markers.clear()
        info.walls.clear()
        before = set(info.names)
        if t is not None:
            self._build_target(t)
        self._target_bodies = set(info.names) - before
        self.target_spec = t
        self.render_cache.clear()

    def _build_target(self, t: TargetSpec) -> None:
        cx, cy = t.center_mm
        Rt = rot_z(np.radians(t.yaw_deg))
        origin = np.array([cx, cy, 0.0])
        fz = self.floor_z
        L, H, th, sep = t.length_mm, t.wall_height_mm, t.wall_thickness_mm, t.separation_mm / 2.0
        ex, ey, ez = np.eye(3)
        # (name, inner-face origin, axis along the wall, inward normal, wall length, box centre,
        #  box half extents), all in the target's own frame (before yaw and centre).
        walls: list[tuple[str, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]]
        walls = [
            (
                "left",
                np.array([-sep, -L / 2.0, fz]),
                ey,
                ex,
                L,
                np.array([-sep - th / 2.0, 0.0, fz + H / 2.0]),
                np.array([th / 2.0, L / 2.0, H / 2.0]),
            ),
            (
                "right",
                np.array([sep, -L / 2.0, fz]),
                ey,
                -ex,
                L,
                np.array([sep + th / 2.0, 0.0, fz + H / 2.0]),
                np.array([th / 2.0, L / 2.0, H / 2.0]),
            ),
        ]
        if t.kind == "three_sided":
            walls.append(
                (
                    "far",
                    np.array([-sep, L / 2.0, fz]),
                    ex,
                    -ey,
                    2 * sep,
                    np.array([0.0, L / 2.0 + th / 2.0, fz + H / 2.0]),
                    np.array([sep + th, th / 2.0, H / 2.0]),
                )
            )
        letters = {
            ("left", "near"): "A",
            ("left", "far"): "B",
            ("right", "far"): "C",
            ("right", "near"): "D",
        }
        for name, o, u, n, length, bc, bh in walls:
            o_S = Rt @ o + origin
            u_S, n_S = Rt @ u, Rt @ n
            rect = Rect(f"wall_{name}", o_S, u_S, ez, length, H, n_S)
            half = t.marker_size_mm / 2.0
            markers = []
            for end, a in (("near", t.marker_inset_mm), ("far", length - t.marker_inset_mm)):
                for level, b in (("border", t.border_height_mm), ("low", t.marker_low_mm)):
                    markers.append(Marker(f"{level}.{end}", (a, b), t.marker_size_mm))
                    corners_ab = np.array(
                        [
                            [a - half, b - half],
                            [a + half, b - half],
                            [a + half, b + half],
                            [a - half, b + half],
                        ]
                    )
                    self.info.markers.append(
                        MarkerTruth(
                            name,
                            f"{level}.{end}",
                            letters.get((name, end), "") if level == "border" else "",
                            rect.point(a, b),
                            rect.point(corners_ab[:, 0], corners_ab[:, 1]),
                        )
                    )
            pattern = WallPattern(
                t.border_height_mm, tuple(markers), t.white.rgb, t.black.rgb, t.marker_color.rgb
            )
            R_box = Rt
            body = self._box(f"wall_{name}", Rt @ bc + origin, R_box, bh, t.edge_color.rgb)
            self.info.panels[body] = Panel(body, rect, pattern)
            for face in box_faces(f"wall_{name}", Rt @ bc + origin, R_box, bh):
                self.info.static_rects.append((face.name, body, face))
            self.info.walls.append(
                {
                    "name": name,
                    "inner_face_origin_mm": o_S,
                    "along_wall": u_S,
                    "normal": n_S,
                    "length_mm": length,
                    "border_segment_S_mm": [
                        rect.point(0.0, t.border_height_mm),
                        rect.point(length, t.border_height_mm),
                    ],
                }
            )

    def _board_rect(
        self, name: str, center: np.ndarray, n: np.ndarray, r: np.ndarray, pattern: CheckerPattern
    ) -> Rect:
        down = np.cross(r, n)
        w, h = pattern.size
        origin = center - r * w / 2.0 - down * h / 2.0
        return Rect(name, origin, r, down, w, h, n)

    def _add_board(
        self, name: str, rect: Rect, pattern: CheckerPattern, thickness: float, on_floor: bool
    ) -> None:
        n, r, down = rect.normal, rect.axis_u, rect.axis_v
        center = rect.point(rect.size_u / 2.0, rect.size_v / 2.0)
        R = np.stack([r, -down, n], axis=1)
        half = np.array([rect.size_u / 2.0, rect.size_v / 2.0, thickness / 2.0])
        body = self._box(f"board_{name}", center - n * thickness / 2.0, R, half, (0.9, 0.9, 0.9))
        self.info.panels[body] = Panel(body, rect, pattern)
        for face in box_faces(f"board_{name}", center - n * thickness / 2.0, R, half):
            self.info.static_rects.append((face.name, body, face))
        corners_ab = pattern.inner_corners_ab()
        corners = rect.point(corners_ab[:, 0], corners_ab[:, 1])
        pose = homogeneous(np.stack([r, down, np.cross(r, down)], axis=1), corners[0])
        self.info.boards.append(
            BoardTruth(
                name,
                (pattern.cols, pattern.rows),
                pattern.square,
                corners,
                pose,
                rect,
                body,
                on_floor,
            )
        )

    def _build_board(self, b: BoardSpec) -> None:
        n = np.asarray(b.normal, float)
        n /= np.linalg.norm(n)
        r = np.asarray(b.right, float)
        r /= np.linalg.norm(r)
        pattern = CheckerPattern(b.inner_corners[0], b.inner_corners[1], b.square_mm, b.margin_mm)
        rect = self._board_rect(b.name, np.asarray(b.center_mm, float), n, r, pattern)
        self._add_board(b.name, rect, pattern, b.thickness_mm, on_floor=False)

    def _build_cube(self, i: int, c: CubeSpec, base_z: float | None = None) -> None:
        half = np.full(3, c.size_mm / 2.0)
        z = self.floor_z if base_z is None else base_z
        centre = np.array([c.position_mm[0], c.position_mm[1], z + c.size_mm / 2.0])
        body = self._box(
            f"cube_{i}_{c.color.name}",
            centre,
            rot_z(np.radians(c.yaw_deg)),
            half,
            c.color.rgb,
            mass=c.mass_kg,
        )
        p.changeDynamics(body, -1, lateralFriction=0.8, physicsClientId=self.client)
        self.info.cubes.append((c, body))

    def add_cube(self, c: CubeSpec) -> int:
        """A cube put down after the world was built, on what is under it; its index."""
        x, y = c.position_mm
        self._build_cube(len(self.info.cubes), c, self.support_z(x, y, c.size_mm, c.yaw_deg))
        return len(self.info.cubes) - 1

    def support_z(self, x_mm: float, y_mm: float, size_mm: float, yaw_deg: float) -> float:
        """The height (S, mm) a cube of `size_mm` put down at (x, y) turned by `yaw_deg` rests
        at: the highest static surface under its footprint (its corners and centre), the floor
        or a board lying on it. A cube set into a board would be pushed out by the contact
        solver over the next steps, so what it reports would depend on when it is read."""
        corners = 0.5 * size_mm * np.array([[0, 0], [1, 1], [1, -1], [-1, 1], [-1, -1]], float)
        c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
        xy = corners @ np.array([[c, s], [-s, c]]) + [x_mm, y_mm]
        top, bottom = self.floor_z + size_mm, self.floor_z - 1.0
        hits = p.rayTestBatch(
            [(px * 1e-3, py * 1e-3, top * 1e-3) for px, py in xy],
            [(px * 1e-3, py * 1e-3, bottom * 1e-3) for px, py in xy],
            physicsClientId=self.client,
        )
        static = self.static_bodies() | {self.floor_body}
        heights = [h[3][2] * 1e3 for h in hits if h[0] in static]
        return max([self.floor_z, *heights])

    def remove_cube(self, index: int) -> None:
        """Take cube `index` out of the world (the later cubes' indices move down by one)."""
        _, body = self.info.cubes.pop(index)
        self._remove_bodies({body})

    def _remove_bodies(self, bodies: set[int]) -> None:
        """Take bodies out of pybullet and out of the records the renderer and truth read."""
        info = self.info
        for body in bodies:
            p.removeBody(body, physicsClientId=self.client)
            info.panels.pop(body, None)
            info.names.pop(body, None)
        info.static_rects = [r for r in info.static_rects if r[1] not in bodies]
        info.boxes = [b for b in info.boxes if b.body not in bodies]

    def _build_bin(self, i: int, b: BinSpec) -> None:
        sx, sy, sz = b.size_mm
        w = b.wall_mm
        R = rot_z(np.radians(b.yaw_deg))
        base = np.array([b.position_mm[0], b.position_mm[1], self.floor_z])
        parts = [
            (np.array([0.0, 0.0, w / 2.0]), np.array([sx / 2.0, sy / 2.0, w / 2.0])),
            (
                np.array([sx / 2.0 - w / 2.0, 0.0, sz / 2.0]),
                np.array([w / 2.0, sy / 2.0, sz / 2.0]),
            ),
            (
                np.array([-sx / 2.0 + w / 2.0, 0.0, sz / 2.0]),
                np.array([w / 2.0, sy / 2.0, sz / 2.0]),
            ),
            (
                np.array([0.0, sy / 2.0 - w / 2.0, sz / 2.0]),
                np.array([sx / 2.0, w / 2.0, sz / 2.0]),
            ),
            (
                np.array([0.0, -sy / 2.0 + w / 2.0, sz / 2.0]),
                np.array([sx / 2.0, w / 2.0, sz / 2.0]),
            ),
        ]
        for k, (offset, half) in enumerate(parts):
            centre = base + R @ offset
            body = self._box(f"bin_{i}_{b.color.name}.{k}", centre, R, half, b.color.rgb)
            for face in box_faces(f"bin_{i}.{k}", centre, R, half):
                self.info.static_rects.append((face.name, body, face))

    def _build_robot(self) -> None:
        robot = self.scene.robot
        assert robot is not None
        T = homogeneous(
            rot_z(np.radians(robot.base_yaw_deg)),
            np.array([robot.base_mm[0], robot.base_mm[1], self.floor_z + robot.pedestal_mm]),
        )
        self.T_S_B = T
        self.ur = ur_model(robot.model)
        self.arm = build_arm(
            self.client,
            self.ur,
            T,
            robot.gripper,
            robot.pedestal_mm,
            [*robot.color.rgb, 1.0],
        )
        self.info.names[self.arm.body] = f"robot_{robot.model}"
        self.set_joints(np.asarray(robot.home_deg, float))
        self.set_fingers(robot.gripper.stroke_mm / 2.0)
        if robot.floor_board is not None:
            fb = robot.floor_board
            pattern = CheckerPattern(
                fb.inner_corners[0], fb.inner_corners[1], fb.square_mm, fb.margin_mm
            )
            yaw = np.deg2rad(fb.yaw_base_deg)
            r = T[:3, :3] @ np.array([np.cos(yaw), np.sin(yaw), 0.0])
            n = np.array([0.0, 0.0, 1.0])
            down = np.cross(r, n)
            first = (
                T[:3, :3] @ np.array([fb.origin_base_mm[0], fb.origin_base_mm[1], 0.0]) + T[:3, 3]
            )
            first[2] = self.floor_z + fb.thickness_mm
            w, h = pattern.size
            corner = first - (fb.margin_mm + fb.square_mm) * (r + down)
            center = corner + r * w / 2.0 + down * h / 2.0
            rect = self._board_rect("floor", center, n, r, pattern)
            self._add_board("floor", rect, pattern, fb.thickness_mm, on_floor=True)

    # ---- state ------------------------------------------------------------------------

    def set_joints(self, q_deg: np.ndarray) -> None:
        """Teleport the arm's six joints (kinematic arm)."""
        assert self.arm is not None
        for j, q in zip(self.arm.joints, q_deg, strict=True):
            p.resetJointState(self.arm.body, j, float(np.deg2rad(q)), physicsClientId=self.client)
        self.version += 1

    def joints(self) -> np.ndarray:
        """The arm's six joint angles (deg)."""
        assert self.arm is not None
        states = p.getJointStates(self.arm.body, list(self.arm.joints), physicsClientId=self.client)
        return np.rad2deg(np.array([s[0] for s in states]))

    def set_fingers(self, half_opening_mm: float) -> None:
        """Place both fingers `half_opening_mm` from the gripper's centre line."""
        assert self.arm is not None
        for j in self.arm.fingers:
            p.resetJointState(self.arm.body, j, half_opening_mm * MM, physicsClientId=self.client)
        self.version += 1

    def tcp_pose_B(self) -> np.ndarray:
        """T_B_tcp (mm) from the DH chain."""
        robot = self.scene.robot
        assert robot is not None
        return tcp_pose(self.ur, self.joints(), robot.gripper.tcp_offset_mm)

    def body_pose(self, body: int) -> np.ndarray:
        """4x4 pose of a body's base in S (mm)."""
        pos, orn = p.getBasePositionAndOrientation(body, physicsClientId=self.client)
        R = Rotation.from_quat(orn).as_matrix()
        return homogeneous(R, np.asarray(pos) / MM)

    def link_pose(self, body: int, link: int) -> np.ndarray:
        """4x4 pose of a link frame in S (mm)."""
        state = p.getLinkState(
            body, link, computeForwardKinematics=True, physicsClientId=self.client
        )
        R = Rotation.from_quat(state[5]).as_matrix()
        return homogeneous(R, np.asarray(state[4]) / MM)

    def step(self, n: int = 1) -> None:
        """Advance the physics by n fixed steps."""
        for _ in range(n):
            p.stepSimulation(physicsClientId=self.client)
        self.sim_time += n * self.time_step
        self.version += 1

    def dynamic_rects(self) -> list[tuple[str, int, Rect]]:
        """The cubes' faces at their current poses."""
        out = []
        for i, (cube, body) in enumerate(self.info.cubes):
            T = self.body_pose(body)
            half = np.full(3, cube.size_mm / 2.0)
            for face in box_faces(f"cube_{i}", T[:3, 3], T[:3, :3], half):
                out.append((face.name, body, face))
        return out

    def static_bodies(self) -> set[int]:
        """Bodies shaded from exact static geometry (never rasterised for the fisheye)."""
        return {b.body for b in self.info.boxes if not b.dynamic} | {
            c.body for c in self.info.cylinders
        }

    def raster_bodies(self) -> list[int]:
        """Bodies the fisheye rasterises: what moves or is not a simple shape (arm, cubes)."""
        hidden = self.static_bodies() | {self.floor_body}
        n = p.getNumBodies(physicsClientId=self.client)
        ids = [p.getBodyUniqueId(i, physicsClientId=self.client) for i in range(n)]
        return [b for b in ids if b not in hidden]

    def analytic_boxes(self) -> list[AnalyticBox]:
        """Every analytically shaded box at its current pose (cubes move)."""
        out = []
        for box in self.info.boxes:
            if box.dynamic:
                T = self.body_pose(box.body)
                box = AnalyticBox(
                    box.name, box.body, T[:3, 3], T[:3, :3], box.half, box.color, True
                )
            out.append(box)
        return out

    def laser_rects(self) -> list[tuple[str, int, Rect]]:
        """Every known planar face the laser plane can meet (static and cubes)."""
        return self.info.static_rects + self.dynamic_rects()

    def close(self) -> None:
        """Disconnect from pybullet; safe to call twice."""
        if self.client >= 0:
            with contextlib.suppress(p.error):
                p.disconnect(physicsClientId=self.client)
            self.client = -1
