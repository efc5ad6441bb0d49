"""Datasets and the `omnisort sim` commands: the calibration screen recovers the renderer's
camera, the Table 3 experiment's layout and names, the "real camera" mode, CLI errors."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.cli import main
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.intrinsics import calibrate_images
from sim_backend.dataset import checkerboard_views, make_dataset, table3_configs
from sim_backend.scene import load_scene, sized
from sim_backend.scene_images import render_scene
from tests.sim.image_measures import stripe_offsets


def test_intrinsic_calibration_on_rendered_views_recovers_the_camera(tmp_path: Path) -> None:
    paths = checkerboard_views(tmp_path, n=10, seed=3, width=960, progress=False)
    assert len(paths) == 10
    truths = [json.loads(p.with_name(p.stem + ".truth.json").read_text()) for p in paths]
    for t in truths:
        assert len(t["checkerboards"]) == 1
        board = t["checkerboards"][0]
        assert board["inner_corners"] == [9, 6] and board["square_mm"] == 116.0
    # The views cover the field: centre and edge (board centres beyond 55 deg off axis).
    model = OcamModel.from_dict(truths[0]["camera"])
    centre_angles = []
    for t in truths:
        uv = np.asarray(t["checkerboards"][0]["corners_px"]).mean(axis=0)
        ray = model.pixel_to_ray(uv[None])[0]
        centre_angles.append(np.rad2deg(np.arccos(ray[2])))
    assert min(centre_angles) < 30.0 and max(centre_angles) > 55.0
    images = [(p.name, cv2.imread(str(p))) for p in paths]
    result = calibrate_images(images, BoardSpec(9, 6, 116.0))
    assert len(result.images_used) >= 9
    uu, vv = np.meshgrid(np.arange(0, 960, 6.0), np.arange(0, 960, 6.0))
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
    true_rays = model.pixel_to_ray(uv)
    inside = true_rays[:, 2] >= np.cos(np.deg2rad(92.5))
    got = result.model.pixel_to_ray(uv)
    angle = np.rad2deg(np.arccos(np.clip(np.sum(true_rays * got, axis=1), -1.0, 1.0)))[inside]
    assert angle.max() < 0.05, angle.max()


def test_a_table3_dataset_through_the_colour_camera(tmp_path: Path) -> None:
    """`effects`: each image is its configuration's scene through `with_camera_effects` (the
    same seed, the same bytes), recorded in the index, and not the plain degraded render."""
    from sim_backend.dataset import render_config, table3_bases
    from sim_backend.scene_images import png_bytes

    index = json.loads(
        make_dataset(
            tmp_path / "fx", "table3", n=1, seed=11, width=240, progress=False, effects=True
        ).read_text()
    )
    assert index["effects"] is True and index["degraded"] is True, index
    cfg = table3_configs(1, 11)[0]
    plain = tmp_path / "plain"
    render_config(plain, cfg, table3_bases(240, scenes=("two_sided",)), 11, True)
    name, base = table3_bases(240, scenes=("two_sided",), effects=True)[0]
    image, _ = render_scene(cfg.apply(base), seed=11 * 100003 + cfg.index * 7, degraded=True)
    written = (tmp_path / "fx" / cfg.folder / f"{name}.png").read_bytes()
    assert written == png_bytes(image)
    assert written != (plain / f"{name}.png").read_bytes()


def test_a_table3_dataset_with_one_effect_left_out(tmp_path: Path) -> None:
    """`degrade`: [degrade] keys over the scenes' (here the mosaic left out), recorded in the
    index; the camera's truth holds the effects drawn, without it."""
    degrade = {"enabled": True, "effects": True, "bayer": False, "bloom": (0.0, 0.0)}
    index = json.loads(
        make_dataset(
            tmp_path, "table3", n=1, seed=11, width=240, progress=False, degrade=degrade
        ).read_text()
    )
    assert index["degraded"] is True and index["degrade"]["bloom"] == [0.0, 0.0], index
    truth = json.loads((tmp_path / "config_000" / "two_sided.truth.json").read_text())
    drawn = truth["degraded"]["effects"]
    assert drawn["bayer"] is False and drawn["bloom"] == 0.0, drawn


def test_table3_dataset_layout(tmp_path: Path) -> None:
    index_path = make_dataset(tmp_path, "table3", n=2, seed=11, width=240, progress=False)
    index = json.loads(index_path.read_text())
    assert index["n"] == 2 and index["seed"] == 11
    configs = table3_configs(2, 11)
    for cfg, entry in zip(configs, index["configs"], strict=True):
        folder = tmp_path / entry["folder"]
        for name in ("two_sided", "three_sided", "checkerboards"):
            image = folder / f"{name}.png"
            truth = json.loads((folder / f"{name}.truth.json").read_text())
            assert truth["image"]["file"] == image.name
            assert truth["image"]["sha256"] == hashlib.sha256(image.read_bytes()).hexdigest()
            rot = truth["camera_rotation"]
            assert (rot["roll_deg"], rot["pitch_deg"], rot["yaw_deg"]) == (
                cfg.camera_roll,
                cfg.camera_pitch,
                cfg.camera_yaw,
            )
            assert truth["laser_plane"]["pitch_deg"] == cfg.laser_pitch
        boards = json.loads((folder / "checkerboards.truth.json").read_text())["checkerboards"]
        for board in boards:
            assert set(board) >= {"inner_corners", "square_mm", "corners_px"}
    angles = np.array(
        [
            [c.camera_roll, c.camera_pitch, c.camera_yaw, c.laser_roll, c.laser_pitch]
            for c in table3_configs(200, 1)
        ]
    )
    assert np.abs(angles).max() <= 10.0 and np.abs(angles).max() > 9.0


def test_real_camera_mode_degrades_but_keeps_the_features() -> None:
    scene = sized(load_scene("two_sided"), 960)
    clean, _ = render_scene(scene, seed=2)
    image, truth = render_scene(scene, seed=2, degraded=True)
    settings = truth["degraded"]
    assert set(settings) >= {
        "noise_read",
        "blur_sigma_px",
        "vignetting",
        "exposure_ev",
        "gamma",
        "jpeg_quality",
        "ambient",
        "laser_speckle",
    }
    # Noise: where the clean image is flat, the degraded one varies from pixel to pixel.
    g_clean = cv2.cvtColor(clean, cv2.COLOR_BGR2GRAY).astype(np.float32)
    g_deg = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(np.float32)
    flat = cv2.blur(g_clean**2, (7, 7)) - cv2.blur(g_clean, (7, 7)) ** 2 < 1e-3
    flat &= g_clean > 20
    assert flat.sum() > 10_000

    def grain(g: np.ndarray) -> float:
        return float(np.std((g - cv2.blur(g, (5, 5)))[flat]))

    assert grain(g_clean) < 0.1 and grain(g_deg) > 0.3
    # Vignetting darkens the edge of the lens circle more than its centre.
    ratio = image.astype(float).mean(axis=2) / np.maximum(clean.astype(float).mean(axis=2), 1)
    assert np.median(ratio[470:490, 60:80]) < np.median(ratio[470:490, 470:490])
    # The stripe is still there and still centred, within what the noise allows.
    offsets = stripe_offsets(image, truth["laser_polylines_px"])
    assert offsets.size > 50 and np.median(np.abs(offsets)) < 0.8


def test_cli_render_and_views(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "render", "two_sided", "--out", str(tmp_path), "--width", "240"]) == 0
    truth = json.loads((tmp_path / "two_sided.truth.json").read_text())
    data = (tmp_path / "two_sided.png").read_bytes()
    assert truth["image"]["sha256"] == hashlib.sha256(data).hexdigest()
    assert truth["camera"]["image_size"] == [240, 240]
    code = main(
        [
            "sim",
            "checkerboard-views",
            "--n",
            "2",
            "--seed",
            "4",
            "--width",
            "320",
            "--out",
            str(tmp_path / "views"),
        ]
    )
    assert code == 0
    listed = json.loads(capsys.readouterr().out.split("\n", 2)[-1])
    assert [Path(p).name for p in listed] == ["view_00.png", "view_01.png"]


def test_cli_bad_scene_is_an_error_naming_the_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[scene]\nname = "x"\n[target]\nkind = "two_sided"\nseparation_mm = -3.0\n')
    assert main(["sim", "render", str(bad), "--out", str(tmp_path)]) == 78
    err = capsys.readouterr().err
    assert "target.separation_mm" in err and "bad_config" in err
    assert not (tmp_path / "x.png").exists()


def test_a_dataset_is_never_rendered_over_with_other_parameters(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`evaluate table3 --data DIR` on a dataset made with other parameters re-rendered 35
    configurations at 1920 px into it (10 minutes, the dataset lost). Now the dataset's own
    parameters are used when left out, and one given that differs is refused by name."""
    from omnisort_hw.cli import build_parser, main
    from omnisort_hw.cli.evaluate_cmd import _dataset_parameters
    from omnisort_hw.errors import InputError

    data = tmp_path / "ds"
    make_dataset(data, "table3", n=1, seed=7, width=240, progress=False)
    before = {p: p.stat().st_mtime_ns for p in data.rglob("*")}
    argv = ["evaluate", "table3", "--data", str(data), "--n", "3", "--width", "480", "--json"]
    assert main(argv) == 2
    error = json.loads(capsys.readouterr().out)["error"]
    assert error["code"] == "bad_input" and str(data) in error["message"], error
    assert "n 1 (asked 3)" in error["message"] and "width 240 (asked 480)" in error["message"]
    assert {p: p.stat().st_mtime_ns for p in data.rglob("*")} == before
    # Left out, the parameters are the dataset's.
    args = build_parser().parse_args(["evaluate", "table3", "--data", str(data)])
    _dataset_parameters(args)
    assert (args.n, args.seed, args.degraded, args.tone_curve) == (1, 7, False, "srgb")
    # Rendering another dataset over it, or into a folder of other files, is refused too.
    with pytest.raises(InputError, match="holds another dataset"):
        make_dataset(data, "table3", n=2, seed=7, width=240, progress=False)
    other = tmp_path / "notes"
    other.mkdir()
    (other / "readme.txt").write_text("mine")
    with pytest.raises(InputError, match=r"holds no dataset\.json"):
        make_dataset(other, "table3", n=1, seed=7, width=240, progress=False)
    with pytest.raises(InputError, match="is a file, not a dataset folder"):
        make_dataset(other / "readme.txt", "table3", n=1, seed=7, width=240, progress=False)
    assert {p: p.stat().st_mtime_ns for p in data.rglob("*")} == before
