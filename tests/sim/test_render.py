"""The renderer is geometrically right, deterministic, and its truth is consistent.

Tolerances: the corner detector and the stripe centroid work on 960 x 960 images; the issue's
limits (0.2 px median for corners, 0.5 px for the stripe) are asserted as stated, and the
measured figures are far below them (about 0.08 px and 0.03 px).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import detect_corners
from sim_backend.fisheye_atlas import geometry_for, remap_flat, render_atlas
from sim_backend.scene import Color, CubeSpec, load_scene, sized
from sim_backend.scene_images import camera_model_for, png_bytes, render_scene
from sim_backend.shading import Shader
from sim_backend.world import SimWorld
from tests.sim.image_measures import corner_errors, only_board, redness, stripe_offsets


def test_checkerboard_corners_agree_with_truth(checkerboards_render) -> None:
    image, truth = checkerboards_render
    boards = truth["checkerboards"]
    assert {b["name"] for b in boards} == {"left", "far"}
    for board in boards:
        assert board["inner_corners"] == [9, 6] and board["square_mm"] == 97.0
        corners = np.asarray(board["corners_px"])
        assert corners.shape == (54, 2)
        found = detect_corners(only_board(image, corners, 60), (9, 6))
        err = corner_errors(found, corners)
        assert np.median(err) <= 0.2, (board["name"], np.median(err))
        assert np.max(err) <= 0.6, (board["name"], np.max(err))


@pytest.mark.parametrize("fixture", ["two_sided_render", "checkerboards_render"])
def test_laser_stripe_centre_agrees_with_truth(fixture: str, request) -> None:
    image, truth = request.getfixturevalue(fixture)
    lines = truth["laser_polylines_px"]
    assert len(lines) >= 2
    offsets = stripe_offsets(image, lines)
    assert offsets.size > 100
    assert np.median(np.abs(offsets)) <= 0.5, np.median(np.abs(offsets))
    assert abs(np.mean(offsets)) <= 0.2


def test_laser_off_draws_no_stripe() -> None:
    scene = sized(load_scene("two_sided"), 480)
    on, truth_on = render_scene(scene)
    off, truth_off = render_scene(scene, laser_on=False)
    assert truth_on["laser_plane"]["on"] and not truth_off["laser_plane"]["on"]
    assert truth_off["laser_polylines_S"] == [] and truth_off["laser_polylines_px"] == []
    # Nothing in the scene itself is as red as the laser (the wall edges' wood is 0.17).
    assert redness(off).max() < 0.25
    assert (redness(on) > 0.3).sum() > 100
    # Away from the stripe the two images are the same.
    near_stripe = cv2.dilate((redness(on) > 0.005).astype(np.uint8), np.ones((7, 7), np.uint8))
    assert np.abs(on.astype(int) - off.astype(int))[near_stripe == 0].max() <= 1


def test_same_scene_and_seed_give_the_same_bytes() -> None:
    scene = sized(load_scene("sorting"), 320)
    a = png_bytes(render_scene(scene, seed=5, with_truth=False)[0])
    b = png_bytes(render_scene(scene, seed=5, with_truth=False)[0])
    assert a == b
    d1 = png_bytes(render_scene(scene, seed=5, degraded=True, with_truth=False)[0])
    d2 = png_bytes(render_scene(scene, seed=5, degraded=True, with_truth=False)[0])
    d3 = png_bytes(render_scene(scene, seed=6, degraded=True, with_truth=False)[0])
    assert d1 == d2
    assert d1 != d3 and d1 != a


def test_markers_are_where_the_truth_says(two_sided_render) -> None:
    image, truth = two_sided_render
    markers = truth["markers_px"]
    assert len(markers) == 8
    assert {m["letter"] for m in markers} == {"A", "B", "C", "D", ""}
    f = image.astype(float) / 255.0
    blue = np.clip(f[..., 0] - np.maximum(f[..., 1], f[..., 2]), 0, None)
    checked = 0
    for m in markers:
        if not m["visible"]:
            continue
        corners = np.asarray(m["corners_px"])
        lo = np.floor(corners.min(axis=0)).astype(int) - 3
        hi = np.ceil(corners.max(axis=0)).astype(int) + 4
        if (hi - lo).min() < 9:
            continue
        win = blue[lo[1] : hi[1], lo[0] : hi[0]]
        # The floor's work area is slightly blue (0.1 on this measure): keep only the marker.
        w = np.clip((win - 0.15) / (win.max() - 0.15), 0.0, 1.0)
        ys, xs = np.mgrid[lo[1] : hi[1], lo[0] : hi[0]]
        centroid = np.array([(w * xs).sum(), (w * ys).sum()]) / w.sum()
        # Area centroid of the projected square (shoelace), what the blue blob's centroid is.
        x, y = corners[:, 0], corners[:, 1]
        cross = x * np.roll(y, -1) - np.roll(x, -1) * y
        area = cross.sum() / 2.0
        poly_c = np.array(
            [((x + np.roll(x, -1)) * cross).sum(), ((y + np.roll(y, -1)) * cross).sum()]
        ) / (6.0 * area)
        assert np.linalg.norm(centroid - poly_c) < 0.3, (m["wall"], m["name"])
        checked += 1
    assert checked >= 4


def test_truth_is_consistent(two_sided_render) -> None:
    image, truth = two_sided_render
    for key in (
        "camera",
        "camera_rotation",
        "laser_plane",
        "target",
        "robot_base",
        "cubes",
        "markers_px",
        "checkerboards",
        "laser_polylines_S",
        "laser_polylines_px",
        "seed",
        "degraded",
        "created",
    ):
        assert key in truth
    json.dumps(truth)
    model = OcamModel.from_dict(truth["camera"])
    assert model.image_size == (image.shape[1], image.shape[0])
    R = np.asarray(truth["camera_rotation"]["matrix"])
    n = np.asarray(truth["laser_plane"]["normal"])
    d = truth["laser_plane"]["distance_mm"]
    surfaces = set()
    for line_s, line_px in zip(
        truth["laser_polylines_S"], truth["laser_polylines_px"], strict=True
    ):
        pts = np.asarray(line_s["points_mm"])
        # On the laser plane through the emitter (0, 0, -d).
        np.testing.assert_allclose((pts - [0.0, 0.0, -d]) @ n, 0.0, atol=1e-3)
        px = np.asarray(line_px["points_px"])
        np.testing.assert_allclose(px[[0, -1]], model.ray_to_pixel(pts @ R), atol=1e-3)
        surfaces.add(line_s["surface"])
    assert {"wall_left.+x", "wall_right.-x"} <= surfaces  # the inner faces of both walls
    target = truth["target"]
    assert target["kind"] == "two_sided" and target["separation_mm"] == 1084.5
    walls = {w["name"]: w for w in target["walls"]}
    gap = np.asarray(walls["right"]["inner_face_origin_mm"]) - walls["left"]["inner_face_origin_mm"]
    assert gap[0] == pytest.approx(1084.5)


def test_a_grazing_stripe_is_centred_on_its_line() -> None:
    # The target tilted as in Table 3 puts the stripe on the floor, which the light meets at
    # about 11 degrees: the band is four times wider there than on the walls, and its off-plane
    # half used to be shadowed by a shadow test made in the plane (0.13-0.24 px off the line).
    from sim_backend.dataset import table3_bases, table3_configs

    base = dict(table3_bases(960, scenes=("two_sided",)))["two_sided"]
    image, truth = render_scene(table3_configs(1, 0)[0].apply(base), seed=1)
    floors = [line for line in truth["laser_polylines_px"] if line["surface"] == "floor"]
    assert floors, "the tilted mounting shows the stripe on the floor"
    for line in truth["laser_polylines_px"]:
        off = stripe_offsets(image, [line])
        if off.size < 30:
            continue
        # A symmetric band is centred within its noise (three standard errors) and the 3x3
        # supersampling's residual quantisation of a 1.3 px wide stripe (0.03 px).
        bound = 3.0 * off.std() / np.sqrt(off.size) + 0.03
        assert abs(off.mean()) <= bound, (line["surface"], off.mean(), bound)


def test_tilted_laser_plane_passes_through_the_emitter() -> None:
    scene = sized(load_scene("two_sided"), 320).replace(laser={"roll_deg": 8.0, "pitch_deg": -6.0})
    _, truth = render_scene(scene)
    n = np.asarray(truth["laser_plane"]["normal"])
    assert n[2] < 0.99
    d = truth["laser_plane"]["distance_mm"]
    for line in truth["laser_polylines_S"]:
        pts = np.asarray(line["points_mm"])
        np.testing.assert_allclose((pts - [0.0, 0.0, -d]) @ n, 0.0, atol=1e-3)


@pytest.mark.parametrize("roll_deg", [0.0, -50.0])
def test_rasterised_bodies_sit_where_the_model_projects_them(roll_deg: float) -> None:
    """What pybullet draws into the cube-map faces lines up with the exact geometry.

    For each cube (drawn by pybullet, then shaded exactly), the pixels the atlas attributes to
    it and the pixels whose ray hits it exactly (both on a 0.25 px grid) have the same
    centroid. This pins pybullet's sampling convention: a half-pixel slip moves the atlas
    centroid by about 0.45 px. Rolling the camera by -50 degrees puts the cubes in side faces.
    """
    # Edges that run along the atlas' pixel rows or columns alias without averaging out, so
    # the cubes are turned by odd angles.
    red = Color("red", (0.85, 0.08, 0.08))
    cubes = tuple(
        CubeSpec(red, 120.0, xy, yaw)
        for xy, yaw in (((-300.0, 500.0), 17.0), ((250.0, 650.0), 33.0), ((0.0, 950.0), 61.0))
    )
    scene = sized(load_scene("sorting"), 960).replace(camera={"roll_deg": roll_deg}, cubes=cubes)
    world = SimWorld(scene)
    model = camera_model_for(scene)
    geo = geometry_for(model, world.R_SC, scene.render.face_px, 185.0)
    shader = Shader(world, render_atlas(world, geo), False)
    faces = set()
    for cube in shader.dynamic:
        centre = world.body_pose(cube.body)[:3, 3]
        uv0 = model.ray_to_pixel(world.R_SC.T @ centre)
        offs = np.arange(-20.0, 20.0, 0.25)
        uu, vv = np.meshgrid(uv0[0] + offs, uv0[1] + offs)
        uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
        rays_c = model.pixel_to_ray(uv)
        rays_s = (rays_c @ world.R_SC.T).astype(np.float32)
        seg = remap_flat(shader.atlas.seg, geo.rays_to_atlas(rays_c), cv2.INTER_NEAREST)
        drawn = seg.astype(int) == cube.body
        # The exact nearest cube along each ray (cubes may hide one another).
        dist = np.full((len(shader.dynamic), len(rays_s)), np.inf, np.float32)
        for j, other in enumerate(shader.dynamic):
            hit, t, _ = Shader._slab(other, rays_s)
            dist[j, hit] = t[hit]
        nearest = np.argmin(dist, axis=0)
        exact = np.isfinite(dist.min(axis=0)) & (
            np.array([b.body for b in shader.dynamic])[nearest] == cube.body
        )
        assert exact.sum() > 2000 and drawn.sum() > 2000
        shift = uv[drawn].mean(axis=0) - uv[exact].mean(axis=0)
        assert np.linalg.norm(shift) < 0.12, (roll_deg, shift)
        assert (drawn & exact).sum() / (drawn | exact).sum() > 0.95
        faces.add(
            geo.faces[
                int(np.argmax(rays_c.mean(axis=0) @ np.array([f.forward for f in geo.faces]).T))
            ].name
        )
    assert (faces == {"front"}) == (roll_deg == 0.0), faces
    world.close()


def test_adaptive_supersampling_matches_full_supersampling() -> None:
    scene = sized(load_scene("sorting"), 320)
    adaptive, _ = render_scene(scene, with_truth=False)
    full, _ = render_scene(scene.replace(render={"adaptive": False}), with_truth=False)
    diff = np.abs(adaptive.astype(int) - full.astype(int))
    assert diff.mean() < 0.15
    assert np.percentile(diff, 99.9) <= 24


def test_renders_through_a_camera_json(tmp_path) -> None:
    ideal = OcamModel.equidistant(960, 960, 190.0)
    model = OcamModel.create(ideal.poly, (483.2, 476.9), (1.002, 0.0015, -0.001), (960, 960))
    path = tmp_path / "camera.json"
    path.write_text(json.dumps({"camera": model.to_dict()}))
    scene = sized(load_scene("checkerboards"), 960).replace(
        camera={"model_file": str(path), "roll_deg": 3.0, "yaw_deg": -4.0}
    )
    image, truth = render_scene(scene)
    got = OcamModel.from_dict(truth["camera"])
    assert got.center_uv == pytest.approx(model.center_uv)
    board = next(b for b in truth["checkerboards"] if b["name"] == "far")
    corners = np.asarray(board["corners_px"])
    found = detect_corners(only_board(image, corners, 60), (9, 6))
    assert np.median(corner_errors(found, corners)) <= 0.2


def test_three_sided_and_sorting_truth() -> None:
    _, three = render_scene(sized(load_scene("three_sided"), 320))
    assert three["target"]["kind"] == "three_sided"
    assert {m["wall"] for m in three["markers_px"]} == {"left", "right", "far"}
    assert any(line["surface"].startswith("wall_far") for line in three["laser_polylines_S"])
    image, sorting = render_scene(sized(load_scene("sorting"), 640))
    base = sorting["robot_base"]
    assert base["xyz_mm"] == pytest.approx([0.0, 1350.0, -1200.0])
    T_SB = np.asarray(base["matrix"])
    assert [b["name"] for b in sorting["checkerboards"]] == ["floor"]
    floor_board = sorting["checkerboards"][0]
    pose_B = np.asarray(floor_board["pose_B"])
    np.testing.assert_allclose(pose_B[:2, 3], [200.0, -180.0], atol=1e-3)
    np.testing.assert_allclose(T_SB @ pose_B, floor_board["pose_S"], atol=1e-3)
    colours = {"red": 2, "green": 1, "blue": 0}
    for cube in sorting["cubes"]:
        np.testing.assert_allclose(T_SB @ np.asarray(cube["pose_B"]), cube["pose_S"], atol=1e-3)
        if cube["colour"] in colours:
            u, v = np.rint(cube["center_px"]).astype(int)
            pixel = image[v, u].astype(int)
            assert int(np.argmax(pixel)) == colours[cube["colour"]], (cube["colour"], pixel)
    # The low laser plane (80 mm above the floor) crosses the 100 mm cubes.
    assert any(line["surface"].startswith("cube_") for line in sorting["laser_polylines_S"])
