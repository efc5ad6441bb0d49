"""Floor-mirror echoes: exact mirror geometry on a synthetic cell (walls, a cube, a glossy floor,
a slightly tilted laser plane and floor), so the partner of every mirror point is known."""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.frames import laser_normal
from omnisort_hw.core.laser_echoes import floor_echoes, floor_mirror_partners

D_MM = 1120.0  # emitter below the viewpoint
FLOOR_N = np.array([0.003, -0.002, 1.0]) / np.linalg.norm([0.003, -0.002, 1.0])
FLOOR_K = -1200.0
LASER_N = laser_normal(np.radians(0.4), np.radians(-0.3))


def on_plane(direction_xy: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Points on the laser plane along horizontal directions from the emitter's axis."""
    xy = direction_xy * ranges[:, None]
    z = (-D_MM * LASER_N[2] - xy @ LASER_N[:2]) / LASER_N[2]
    return np.column_stack([xy, z])


def mirror_points(direct: np.ndarray) -> np.ndarray:
    """Where the camera sees each direct point's mirror image in the floor, mapped to the laser
    plane (its ray meets the plane before the floor)."""
    image = direct - 2.0 * ((direct @ FLOOR_N) - FLOOR_K)[:, None] * FLOOR_N
    t = (-D_MM * LASER_N[2]) / (image @ LASER_N)
    return image * t[:, None]


def test_the_partner_of_a_mirror_point_is_its_direct_point() -> None:
    angles = np.radians(np.linspace(20, 160, 50))
    direct = on_plane(np.column_stack([np.cos(angles), np.sin(angles)]), np.full(50, 800.0))
    partners = floor_mirror_partners(mirror_points(direct), LASER_N, D_MM, FLOOR_N, FLOOR_K)
    assert np.abs(partners - direct).max() < 1e-6


def test_mirror_points_are_dropped_whatever_their_strength_and_real_points_kept() -> None:
    rng = np.random.default_rng(3)
    a_wall = np.radians(np.linspace(30, 150, 120))
    wall = on_plane(np.column_stack([np.cos(a_wall), np.sin(a_wall)]), 750.0 / np.sin(a_wall))
    a_cube = np.radians(np.linspace(85, 95, 12))  # a cube in front of the wall (shadows it)
    cube = on_plane(np.column_stack([np.cos(a_cube), np.sin(a_cube)]), 500.0 / np.sin(a_cube))
    behind = np.abs(np.degrees(a_wall) - 90.0) <= 5.5
    seen_wall = wall[~behind]
    echoes = mirror_points(seen_wall[::3])
    # 0.2 mm of mapping noise (a tenth of a pixel at this range)
    pts = np.concatenate([seen_wall, cube, echoes])
    pts = pts + rng.normal(0.0, 0.2, pts.shape)
    is_echo = np.r_[np.zeros(len(seen_wall) + len(cube), bool), np.ones(len(echoes), bool)]
    got = floor_echoes(pts, LASER_N, D_MM, FLOOR_N, FLOOR_K)
    assert np.array_equal(got, is_echo)
    # without the floor's mirror image of the wall behind it, the cube is kept too
    assert not floor_echoes(cube, LASER_N, D_MM, FLOOR_N, FLOOR_K).any()


def test_nan_points_and_a_floor_above_the_plane_give_no_echoes() -> None:
    pts = on_plane(np.array([[0.0, 1.0]]), np.array([600.0, 900.0]))
    pts = np.vstack([pts, [np.nan, np.nan, np.nan]])
    assert not floor_echoes(pts, LASER_N, D_MM, FLOOR_N, FLOOR_K).any()
    assert not floor_echoes(pts, LASER_N, D_MM, FLOOR_N, -500.0).any()


def test_the_floor_comes_from_the_registered_robot_base() -> None:
    from types import SimpleNamespace

    from omnisort_hw.pipeline.laser_map import floor_plane_S

    T = np.eye(4)
    T[:3, 3] = (100.0, 650.0, -1200.0)  # the base on the floor, 1.2 m below the camera
    calib = SimpleNamespace(robot_base={"matrix": T.tolist()})
    n, k = floor_plane_S(calib)  # type: ignore[arg-type, misc]
    assert np.allclose(n, (0.0, 0.0, 1.0)) and k == -1200.0
    _, k2 = floor_plane_S(calib, SimpleNamespace(floor_z_B_mm=-5.0))  # type: ignore[arg-type, misc]
    assert k2 == -1205.0
    assert floor_plane_S(SimpleNamespace(robot_base=None)) is None  # type: ignore[arg-type]
