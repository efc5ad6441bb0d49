"""Scene description files (TOML) for the simulated cell: schema, defaults and validation.

Everything is in the system frame S (docs/frames.md): origin at the camera viewpoint, Z up, the
target walls along Y. Millimetres and degrees. The floor is at Z = -camera.height_mm.

A scene file is parsed against the dataclasses below: an unknown key, a missing required
field, a wrong type or an impossible geometry is a `ConfigError` whose message names the field
as a dotted path (`target.separation_mm`, `cubes[2].position_mm`). Sections left out take
their defaults; `target` and `robot` are absent unless given. The shipped scenes live in
`sim_backend/scenes/` and are documented there.

Over 600 lines: the scene file's schema, mostly declarations (one dataclass per section) and
the checks that name a bad field by its dotted path.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, get_args, get_origin

import numpy as np

from omnisort_hw.config.toml_file import read_toml
from omnisort_hw.errors import ConfigError

SCENES_DIR = Path(__file__).resolve().parent / "scenes"
TONE_CURVES = ("srgb", "linear")

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]

NAMED_COLORS: dict[str, Vec3] = {
    "red": (0.85, 0.08, 0.08),
    "green": (0.08, 0.62, 0.18),
    "blue": (0.08, 0.32, 0.85),
    "yellow": (0.92, 0.80, 0.10),
    "black": (0.06, 0.06, 0.06),
    "white": (0.92, 0.92, 0.92),
    "orange": (0.95, 0.45, 0.08),
    "grey": (0.5, 0.5, 0.5),
}


@dataclass(frozen=True)
class Color:
    """A named colour or an RGB triple in [0, 1]; `name` is kept for truth files."""

    name: str
    rgb: Vec3


def _color(value: object, path: str) -> Color:
    if isinstance(value, str):
        key = value.strip().lower()
        if key not in NAMED_COLORS:
            raise ConfigError(f"{path}: unknown colour {value!r} (known: {sorted(NAMED_COLORS)})")
        return Color(key, NAMED_COLORS[key])
    rgb = _floats(value, 3, path)
    if min(rgb) < 0.0 or max(rgb) > 1.0:
        raise ConfigError(f"{path}: RGB components must be in [0, 1], got {list(rgb)}")
    return Color("rgb", (rgb[0], rgb[1], rgb[2]))


def _floats(value: object, n: int, path: str) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise ConfigError(f"{path}: expected a list of {n} numbers, got {value!r}")
    out = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, int | float):
            raise ConfigError(f"{path}: expected numbers, got {item!r}")
        if not np.isfinite(item):
            raise ConfigError(f"{path}: expected finite numbers, got {item!r}")
        out.append(float(item))
    return tuple(out)


# ---- schema -------------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneInfo:
    """`[scene]`: a name (used for output files) and a free description."""

    name: str
    description: str = ""


@dataclass(frozen=True)
class CameraSpec:
    """`[camera]`: the fisheye on the boom. `model_file` (a camera.json, relative to the scene
    file) replaces the ideal equidistant model of `fov_deg`; beyond `image_circle_fov_deg` the
    lens gives nothing (black)."""

    width: int = 1920
    height: int = 1920
    fov_deg: float = 185.0
    model_file: str = ""
    image_circle_fov_deg: float = 185.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    yaw_deg: float = 0.0
    height_mm: float = 1200.0


@dataclass(frozen=True)
class LaserSpec:
    """`[laser]`: the line emitter d below the camera. The stripe is a Gaussian across the plane
    of full width at half maximum `width_mm`; its intensity falls as (reference_range/range)^falloff
    and it hides `surface_hide` of the surface colour where it is brightest."""

    on: bool = True
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    distance_mm: float = 800.0
    width_mm: float = 4.0
    intensity: float = 1.0
    falloff: float = 1.0
    reference_range_mm: float = 1000.0
    color: Color = Color("rgb", (1.0, 0.06, 0.04))
    surface_hide: float = 0.75


@dataclass(frozen=True)
class RenderSpec:
    """`[render]`: cube-map face resolution, supersampling (k x k samples on pixels with edges,
    stripe or pattern changes; every pixel when `adaptive` is false), a simple light, and the
    camera's tone curve: "srgb" (colours are sRGB-encoded as in any content pipeline, light is
    mixed linearly by supersampling, blur and laser, and the image is sRGB-encoded, as real
    cameras and the authors' Unity renders do) or "linear" (values written as computed, the
    default: the shipped scenes' colours, laser and thresholds were tuned that way; the Table 3
    datasets render "srgb")."""

    face_px: int = 1024
    supersampling: int = 3
    adaptive: bool = True
    ambient: float = 0.8
    diffuse: float = 0.25
    light_direction: Vec3 = (0.25, -0.35, 1.0)
    sky_color: Color = Color("rgb", (0.78, 0.80, 0.82))
    hall_color: Color = Color("rgb", (0.46, 0.46, 0.45))
    tone_curve: str = "linear"


@dataclass(frozen=True)
class FloorSpec:
    """`[floor]`: an infinite floor with a rectangular work area of another colour."""

    color: Color = Color("rgb", (0.40, 0.41, 0.42))
    work_area_mm: tuple[float, float, float, float] = (-1000.0, 1000.0, -700.0, 1700.0)
    work_area_color: Color = Color("rgb", (0.42, 0.48, 0.58))


@dataclass(frozen=True)
class BoomSpec:
    """`[boom]`: the laser emitter housing on the Z axis and the rod that holds it (towards -Y)."""

    enabled: bool = True
    housing_radius_mm: float = 45.0
    housing_height_mm: float = 60.0
    rod_radius_mm: float = 18.0
    rod_length_mm: float = 900.0
    color: Color = Color("rgb", (0.55, 0.56, 0.58))


@dataclass(frozen=True)
class TargetSpec:
    """`[target]`: the two-sided (or three-sided) calibration target of docs/frames.md.

    The inner faces of the side walls are at X = center.x -/+ separation/2 (before `yaw_deg`
    about the centre), running along Y over `length_mm` centred on `center_mm[1]`. Markers:
    squares of `marker_size_mm` centred `marker_inset_mm` from each wall end, on the border
    line and at `marker_low_mm` above the floor. `three_sided` adds a far wall at the +Y end.
    """

    kind: str
    separation_mm: float = 1084.5
    length_mm: float = 1084.5
    center_mm: Vec2 = (0.0, 650.0)
    yaw_deg: float = 0.0
    wall_height_mm: float = 1000.0
    wall_thickness_mm: float = 30.0
    border_height_mm: float = 750.0
    marker_size_mm: float = 50.0
    marker_inset_mm: float = 60.0
    marker_low_mm: float = 60.0
    white: Color = Color("rgb", (0.97, 0.97, 0.97))
    black: Color = Color("rgb", (0.05, 0.05, 0.05))
    marker_color: Color = Color("rgb", (0.05, 0.42, 0.95))
    edge_color: Color = Color("rgb", (0.85, 0.68, 0.50))


@dataclass(frozen=True)
class BoardSpec:
    """`[[checkerboards]]`: a checkerboard of `inner_corners` = [cols, rows] and `square_mm`,
    centred at `center_mm`, its front facing `normal`, its columns running along `right`.
    The square at the top-left (first row, first column) is black; a white margin surrounds
    the squares."""

    name: str
    center_mm: Vec3
    normal: Vec3
    right: Vec3
    inner_corners: tuple[int, int] = (9, 6)
    square_mm: float = 97.0
    margin_mm: float = 40.0
    thickness_mm: float = 8.0


@dataclass(frozen=True)
class CubeSpec:
    """`[[cubes]]`: a cube resting on the floor at `position_mm` = [x, y], turned by `yaw_deg`."""

    color: Color
    size_mm: float
    position_mm: Vec2
    yaw_deg: float = 0.0
    mass_kg: float = 0.3


@dataclass(frozen=True)
class BinSpec:
    """`[[bins]]`: an open box on the floor for one colour, outer size [x, y, z] mm."""

    color: Color
    position_mm: Vec2
    size_mm: Vec3 = (300.0, 300.0, 150.0)
    wall_mm: float = 10.0
    yaw_deg: float = 0.0


@dataclass(frozen=True)
class FloorBoardSpec:
    """`[robot.floor_board]`: the registration checkerboard lying on the floor at a fixed pose in
    the robot base frame B: its first inner corner at `origin_base_mm` = [x, y], columns along the
    direction `yaw_base_deg` from B's x axis."""

    origin_base_mm: Vec2 = (250.0, -200.0)
    yaw_base_deg: float = 0.0
    inner_corners: tuple[int, int] = (9, 6)
    square_mm: float = 50.0
    margin_mm: float = 30.0
    thickness_mm: float = 2.0


@dataclass(frozen=True)
class GripperSpec:
    """`[robot.gripper]`: a parallel gripper; a cube narrower than `stroke_mm` between the
    fingers is grasped (fixed constraint) when it closes."""

    stroke_mm: float = 150.0
    finger_length_mm: float = 60.0
    body_length_mm: float = 90.0
    tcp_offset_mm: float = 140.0


@dataclass(frozen=True)
class RobotSpec:
    """`[robot]`: a UR arm on the floor at `base_mm` = [x, y] turned by `base_yaw_deg` about Z.
    `home_deg` are the joints at start; speeds bound every move."""

    model: str = "UR5e"
    base_mm: Vec2 = (0.0, 1450.0)
    base_yaw_deg: float = -90.0
    pedestal_mm: float = 0.0
    home_deg: tuple[float, float, float, float, float, float] = (
        180.0,
        -60.0,
        -120.0,
        -90.0,
        90.0,
        0.0,
    )
    joint_speed_deg_s: float = 90.0
    linear_speed_mm_s: float = 250.0
    color: Color = Color("rgb", (0.72, 0.74, 0.76))
    floor_board: FloorBoardSpec | None = None
    gripper: GripperSpec = field(default_factory=GripperSpec)


@dataclass(frozen=True)
class DegradeSpec:
    """`[degrade]`: the "real camera" mode. Each [lo, hi] range is sampled with the render seed,
    so the same seed gives the same degradation; give lo = hi for a fixed value."""

    enabled: bool = False
    noise_read: Vec2 = (0.006, 0.016)
    noise_shot: Vec2 = (0.006, 0.016)
    blur_sigma_px: Vec2 = (0.4, 1.1)
    vignetting: Vec2 = (0.15, 0.45)
    exposure_ev: Vec2 = (-0.4, 0.3)
    gamma: Vec2 = (0.85, 1.2)
    jpeg_quality: tuple[int, int] = (70, 95)
    ambient: Vec2 = (0.0, 0.06)
    laser_uneven: Vec2 = (0.2, 0.5)
    laser_speckle: Vec2 = (0.2, 0.5)
    # The colour camera's effects (`camera_effects`), on request; the ranges are measured on
    # real photographs (docs/real_light.md), the crosstalk follows the laser's colour.
    effects: bool = False
    chromatic_red_px: Vec2 = (0.15, 0.35)  # radial shift from green at the corner, outward
    chromatic_blue_px: Vec2 = (-0.1, 0.75)
    bloom: Vec2 = (0.05, 0.15)
    bloom_sigma_px: Vec2 = (14.0, 24.0)
    bayer: bool = True


@dataclass(frozen=True)
class Scene:
    """A whole scene file. `base_dir` resolves relative paths (the camera model file)."""

    scene: SceneInfo
    camera: CameraSpec = field(default_factory=CameraSpec)
    laser: LaserSpec = field(default_factory=LaserSpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    floor: FloorSpec = field(default_factory=FloorSpec)
    boom: BoomSpec = field(default_factory=BoomSpec)
    degrade: DegradeSpec = field(default_factory=DegradeSpec)
    target: TargetSpec | None = None
    robot: RobotSpec | None = None
    checkerboards: tuple[BoardSpec, ...] = ()
    cubes: tuple[CubeSpec, ...] = ()
    bins: tuple[BinSpec, ...] = ()
    base_dir: str = ""

    @property
    def name(self) -> str:
        """The scene's name."""
        return self.scene.name

    @property
    def floor_z(self) -> float:
        """Z of the floor in S (mm)."""
        return -self.camera.height_mm

    def replace(self, **changes: Any) -> Scene:
        """A copy with top-level sections replaced; section values may be dicts of field changes.

        `scene.replace(camera={"roll_deg": 3.0})` changes one field of a section. The result is
        validated like a file.
        """
        updates: dict[str, Any] = {}
        for key, value in changes.items():
            current = getattr(self, key)
            if (
                isinstance(value, dict)
                and dataclasses.is_dataclass(current)
                and not isinstance(current, type)
            ):
                hints = typing.get_type_hints(type(current))
                fields = {f.name for f in dataclasses.fields(current)}
                parsed = {}
                for name, v in value.items():
                    if name not in fields:
                        raise ConfigError(f"{key}.{name}: unknown key")
                    parsed[name] = _parse_value(hints[name], v, f"{key}.{name}")
                updates[key] = dataclasses.replace(current, **parsed)
            else:
                updates[key] = value
        new = dataclasses.replace(self, **updates)
        validate_scene(new)
        return new


# ---- generic parser -----------------------------------------------------------------------


def _parse_value(tp: Any, value: object, path: str) -> Any:
    """Convert a TOML value to the annotated type `tp`, or raise ConfigError naming `path`."""
    origin = get_origin(tp)
    if isinstance(tp, type) and type(value) is tp:
        return value
    if tp is Color:
        return _color(value, path)
    if origin in (types.UnionType, typing.Union):
        inner = [a for a in get_args(tp) if a is not type(None)]
        return _parse_value(inner[0], value, path)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{path}: expected a table, got {value!r}")
        return _parse_dataclass(tp, value, path)
    if origin is tuple:
        args = get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            if not isinstance(value, list):
                raise ConfigError(f"{path}: expected an array of tables, got {value!r}")
            return tuple(_parse_value(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if all(a is int for a in args):
            vals = _floats(value, len(args), path)
            if any(v != int(v) for v in vals):
                raise ConfigError(f"{path}: expected whole numbers, got {value!r}")
            return tuple(int(v) for v in vals)
        return _floats(value, len(args), path)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: expected a whole number, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{path}: expected a number, got {value!r}")
        if not np.isfinite(value):
            raise ConfigError(f"{path}: expected a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {value!r}")
        return value
    raise TypeError(f"unsupported schema type {tp!r} at {path}")


def _parse_dataclass(cls: Any, data: dict[str, Any], path: str) -> Any:
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls) if f.name != "base_dir"}
    prefix = f"{path}." if path else ""
    for key in data:
        if key not in known:
            raise ConfigError(
                f"{prefix}{key}: unknown key (known keys here: {', '.join(sorted(known))})"
            )
    kwargs: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if f.name == "base_dir":
            continue
        if f.name in data:
            kwargs[f.name] = _parse_value(hints[f.name], data[f.name], f"{prefix}{f.name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{prefix}{f.name}: missing required field")
    return cls(**kwargs)


# ---- semantic checks ----------------------------------------------------------------------


def _positive(value: float, path: str, strict: bool = True) -> None:
    if value < 0.0 or (strict and value == 0.0):
        raise ConfigError(f"{path}: must be {'> 0' if strict else '>= 0'}, got {value}")


def _in_range(value: float, lo: float, hi: float, path: str) -> None:
    if not lo <= value <= hi:
        raise ConfigError(f"{path}: must be within [{lo}, {hi}], got {value}")


def _unit(vec: Vec3, path: str) -> np.ndarray:
    arr = np.asarray(vec, float)
    norm = float(np.linalg.norm(arr))
    if norm < 1e-9:
        raise ConfigError(f"{path}: must be a non-zero direction, got {list(vec)}")
    return arr / norm


def _check_range_pairs(spec: DegradeSpec) -> None:
    for f in dataclasses.fields(spec):
        value = getattr(spec, f.name)
        if isinstance(value, tuple) and value[0] > value[1]:
            raise ConfigError(f"degrade.{f.name}: range [lo, hi] needs lo <= hi, got {list(value)}")
    _in_range(spec.jpeg_quality[0], 1, 100, "degrade.jpeg_quality")
    _in_range(spec.jpeg_quality[1], 1, 100, "degrade.jpeg_quality")
    for name in (
        "noise_read",
        "noise_shot",
        "blur_sigma_px",
        "ambient",
        "laser_uneven",
        "bloom_sigma_px",
    ):
        _positive(getattr(spec, name)[0], f"degrade.{name}", strict=False)
    _positive(spec.gamma[0], "degrade.gamma")
    _in_range(spec.vignetting[0], 0.0, 1.0, "degrade.vignetting")
    _in_range(spec.vignetting[1], 0.0, 1.0, "degrade.vignetting")
    _in_range(spec.laser_speckle[0], 0.0, 1.0, "degrade.laser_speckle")
    _in_range(spec.laser_speckle[1], 0.0, 1.0, "degrade.laser_speckle")
    _in_range(spec.bloom[0], 0.0, 1.0, "degrade.bloom")
    _in_range(spec.bloom[1], 0.0, 1.0, "degrade.bloom")


def _check_target(t: TargetSpec, floor_z: float) -> None:
    if t.kind not in ("two_sided", "three_sided"):
        raise ConfigError(f"target.kind: must be 'two_sided' or 'three_sided', got {t.kind!r}")
    for name in (
        "separation_mm",
        "length_mm",
        "wall_height_mm",
        "wall_thickness_mm",
        "border_height_mm",
        "marker_size_mm",
        "marker_low_mm",
    ):
        _positive(getattr(t, name), f"target.{name}")
    if t.border_height_mm >= t.wall_height_mm:
        raise ConfigError(
            f"target.border_height_mm: the border ({t.border_height_mm} mm) must be below the "
            f"top of the wall (wall_height_mm = {t.wall_height_mm})"
        )
    half = t.marker_size_mm / 2.0
    if t.marker_inset_mm - half < 0.0 or t.marker_inset_mm + half > t.length_mm / 2.0:
        raise ConfigError(
            f"target.marker_inset_mm: markers of {t.marker_size_mm} mm centred "
            f"{t.marker_inset_mm} mm from the wall ends fall outside the wall "
            f"(length_mm = {t.length_mm})"
        )
    if t.marker_low_mm - half < 0.0 or t.marker_low_mm + half >= t.border_height_mm - half:
        raise ConfigError(
            f"target.marker_low_mm: the lower markers ({t.marker_low_mm} mm, size "
            f"{t.marker_size_mm}) must lie on the white part between the floor and the border "
            f"markers (border_height_mm = {t.border_height_mm})"
        )
    if t.border_height_mm + half > t.wall_height_mm:
        raise ConfigError(
            "target.marker_size_mm: the border markers stick out above the top of the wall"
        )
    if t.wall_height_mm >= -floor_z:
        raise ConfigError(
            f"target.wall_height_mm: walls of {t.wall_height_mm} mm reach the camera "
            f"(camera.height_mm = {-floor_z})"
        )


def _check_boards(boards: tuple[BoardSpec, ...]) -> None:
    names = set()
    for i, b in enumerate(boards):
        path = f"checkerboards[{i}]"
        if b.name in names:
            raise ConfigError(f"{path}.name: duplicate board name {b.name!r}")
        names.add(b.name)
        if b.inner_corners[0] < 2 or b.inner_corners[1] < 2:
            raise ConfigError(f"{path}.inner_corners: need at least 2 x 2, got {b.inner_corners}")
        _positive(b.square_mm, f"{path}.square_mm")
        _positive(b.margin_mm, f"{path}.margin_mm", strict=False)
        _positive(b.thickness_mm, f"{path}.thickness_mm")
        n = _unit(b.normal, f"{path}.normal")
        r = _unit(b.right, f"{path}.right")
        if abs(float(n @ r)) > 1e-6:
            raise ConfigError(f"{path}.right: must be perpendicular to {path}.normal")


def _footprint(center: Vec2, half: Vec2, yaw_deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(yaw_deg)), np.sin(np.deg2rad(yaw_deg))
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * np.asarray(half)
    return corners @ np.array([[c, s], [-s, c]]) + np.asarray(center)


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test of two convex polygons (4, 2)."""
    for poly in (a, b):
        for i in range(len(poly)):
            edge = poly[(i + 1) % len(poly)] - poly[i]
            axis = np.array([-edge[1], edge[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() <= pb.min() + 1e-9 or pb.max() <= pa.min() + 1e-9:
                return False
    return True


def wall_footprints(t: TargetSpec) -> list[tuple[str, np.ndarray]]:
    """Floor footprints (4, 2) of the target's walls in S, for overlap checks."""
    cx, cy = t.center_mm
    half_len = t.length_mm / 2.0
    th = t.wall_thickness_mm
    sep = t.separation_mm / 2.0
    c, s = np.cos(np.deg2rad(t.yaw_deg)), np.sin(np.deg2rad(t.yaw_deg))
    rot = np.array([[c, s], [-s, c]])
    local = [
        ("left", np.array([-sep - th / 2.0, 0.0]), (th / 2.0, half_len)),
        ("right", np.array([sep + th / 2.0, 0.0]), (th / 2.0, half_len)),
    ]
    if t.kind == "three_sided":
        local.append(("far", np.array([0.0, half_len + th / 2.0]), (sep + th, th / 2.0)))
    out = []
    for name, centre, half in local:
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * np.asarray(half)
        out.append((name, (corners + centre) @ rot + np.array([cx, cy])))
    return out


def _check_objects(scene: Scene) -> None:
    walls = wall_footprints(scene.target) if scene.target else []
    prints: list[tuple[str, np.ndarray]] = [(f"target wall {n}", fp) for n, fp in walls]
    height = scene.camera.height_mm
    for i, cube in enumerate(scene.cubes):
        path = f"cubes[{i}]"
        _positive(cube.size_mm, f"{path}.size_mm")
        _positive(cube.mass_kg, f"{path}.mass_kg")
        if cube.size_mm >= height:
            raise ConfigError(f"{path}.size_mm: a {cube.size_mm} mm cube reaches the camera")
        fp = _footprint(cube.position_mm, (cube.size_mm / 2.0,) * 2, cube.yaw_deg)
        for other, ofp in prints:
            if _overlap(fp, ofp):
                raise ConfigError(f"{path}.position_mm: the cube intersects {other}")
        prints.append((f"cubes[{i}]", fp))
    for i, b in enumerate(scene.bins):
        path = f"bins[{i}]"
        for k, v in enumerate(b.size_mm):
            _positive(v, f"{path}.size_mm[{k}]")
        _positive(b.wall_mm, f"{path}.wall_mm")
        if 2 * b.wall_mm >= min(b.size_mm[0], b.size_mm[1]):
            raise ConfigError(f"{path}.wall_mm: walls of {b.wall_mm} mm leave no inside")
        fp = _footprint(b.position_mm, (b.size_mm[0] / 2.0, b.size_mm[1] / 2.0), b.yaw_deg)
        for other, ofp in prints:
            if _overlap(fp, ofp):
                raise ConfigError(f"{path}.position_mm: the bin intersects {other}")
        prints.append((f"bins[{i}]", fp))


def validate_scene(scene: Scene) -> None:
    """Semantic checks; raises ConfigError naming the first impossible field."""
    cam = scene.camera
    _positive(cam.width, "camera.width")
    _positive(cam.height, "camera.height")
    _in_range(cam.fov_deg, 60.0, 300.0, "camera.fov_deg")
    _in_range(cam.image_circle_fov_deg, 10.0, 360.0, "camera.image_circle_fov_deg")
    _positive(cam.height_mm, "camera.height_mm")
    for name in ("roll_deg", "pitch_deg", "yaw_deg"):
        _in_range(getattr(cam, name), -180.0, 180.0, f"camera.{name}")
    las = scene.laser
    _positive(las.distance_mm, "laser.distance_mm")
    if las.distance_mm >= cam.height_mm:
        raise ConfigError(
            f"laser.distance_mm: the emitter ({las.distance_mm} mm below the camera) would be "
            f"under the floor (camera.height_mm = {cam.height_mm})"
        )
    _in_range(las.roll_deg, -80.0, 80.0, "laser.roll_deg")
    _in_range(las.pitch_deg, -80.0, 80.0, "laser.pitch_deg")
    _positive(las.width_mm, "laser.width_mm")
    _positive(las.intensity, "laser.intensity", strict=False)
    _positive(las.falloff, "laser.falloff", strict=False)
    _positive(las.reference_range_mm, "laser.reference_range_mm")
    _in_range(las.surface_hide, 0.0, 1.0, "laser.surface_hide")
    ren = scene.render
    _in_range(ren.face_px, 64, 4096, "render.face_px")
    _in_range(ren.supersampling, 1, 8, "render.supersampling")
    _unit(ren.light_direction, "render.light_direction")
    _positive(ren.ambient, "render.ambient", strict=False)
    _positive(ren.diffuse, "render.diffuse", strict=False)
    if ren.tone_curve not in TONE_CURVES:
        raise ConfigError(
            f"render.tone_curve must be one of {', '.join(TONE_CURVES)}, got {ren.tone_curve!r}"
        )
    wa = scene.floor.work_area_mm
    if wa[0] >= wa[1] or wa[2] >= wa[3]:
        raise ConfigError(f"floor.work_area_mm: expected [xmin, xmax, ymin, ymax], got {list(wa)}")
    boom = scene.boom
    for name in ("housing_radius_mm", "housing_height_mm", "rod_radius_mm", "rod_length_mm"):
        _positive(getattr(boom, name), f"boom.{name}")
    if boom.enabled and boom.housing_height_mm / 2.0 >= las.distance_mm:
        raise ConfigError("boom.housing_height_mm: the emitter housing reaches the camera")
    if scene.target is not None:
        _check_target(scene.target, scene.floor_z)
    _check_boards(scene.checkerboards)
    _check_objects(scene)
    if scene.robot is not None:
        _check_robot(scene.robot)
    _check_range_pairs(scene.degrade)


def _check_robot(robot: RobotSpec) -> None:
    from omnisort_hw.core.kinematics import UR_MODELS

    if robot.model.lower() not in UR_MODELS:
        raise ConfigError(
            f"robot.model: unknown model {robot.model!r} (known: {', '.join(UR_MODELS)})"
        )
    _positive(robot.pedestal_mm, "robot.pedestal_mm", strict=False)
    _positive(robot.joint_speed_deg_s, "robot.joint_speed_deg_s")
    _positive(robot.linear_speed_mm_s, "robot.linear_speed_mm_s")
    g = robot.gripper
    for name in ("stroke_mm", "finger_length_mm", "body_length_mm", "tcp_offset_mm"):
        _positive(getattr(g, name), f"robot.gripper.{name}")
    fb = robot.floor_board
    if fb is not None:
        if fb.inner_corners[0] < 2 or fb.inner_corners[1] < 2:
            raise ConfigError("robot.floor_board.inner_corners: need at least 2 x 2")
        _positive(fb.square_mm, "robot.floor_board.square_mm")
        _positive(fb.thickness_mm, "robot.floor_board.thickness_mm")
        _positive(fb.margin_mm, "robot.floor_board.margin_mm", strict=False)


# ---- loading ------------------------------------------------------------------------------


def scene_from_dict(data: dict[str, Any], base_dir: str | Path = "", source: str = "") -> Scene:
    """Build and validate a Scene from parsed TOML; errors name `source` and the field."""
    try:
        scene = _parse_dataclass(Scene, data, "")
        scene = dataclasses.replace(scene, base_dir=str(base_dir))
        validate_scene(scene)
    except ConfigError as exc:
        raise ConfigError(f"scene {source}: {exc}" if source else str(exc)) from None
    return scene


def load_scene(path: str | Path) -> Scene:
    """Read a scene file; a bare name (e.g. "two_sided") picks a shipped scene."""
    p = Path(path)
    if not p.exists() and not p.suffix and (SCENES_DIR / f"{p.name}.toml").exists():
        p = SCENES_DIR / f"{p.name}.toml"
    return scene_from_dict(read_toml(p, "scene file"), p.parent, str(p))


def sized(scene: Scene, width: int | None, height: int | None = None) -> Scene:
    """The scene rendered at another image size; the cube-map faces scale with the width."""
    if width is None or (width == scene.camera.width and (height or width) == scene.camera.height):
        return scene
    face = max(64, round(scene.render.face_px * width / scene.camera.width))
    return scene.replace(
        camera={"width": int(width), "height": int(height or width)}, render={"face_px": face}
    )


def with_camera_effects(scene: Scene) -> Scene:
    """The scene through the "real camera" with the colour camera's effects (crosstalk,
    chromatic aberration, bloom, Bayer demosaicing: `camera_effects`), as a scene file's
    `[degrade] enabled = true` and `effects = true` ask."""
    return scene.replace(degrade={"enabled": True, "effects": True})


def shipped_scenes() -> list[str]:
    """Names of the scenes shipped in `sim_backend/scenes`."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))
