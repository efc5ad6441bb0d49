"""The laser map use case: every point with its pixel, and dashed stripes kept whole."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.frames import camera_rotation
from omnisort_hw.core.mapping import segments


def level_system(width: int = 960) -> SystemCalibration:
    """Camera looking straight down, laser plane horizontal 900 mm below it."""
    return SystemCalibration(
        model=OcamModel.equidistant(width, width, 185.0),
        R_SC=camera_rotation(0.0, 0.0, 0.0),
        laser_normal=np.array([0.0, 0.0, 1.0]),
        laser_distance_mm=900.0,
        method="test",
    )


def _line(x0: float, x1: float, y: float, step_mm: float, mm_per_px: float) -> tuple:
    """Points along X at Y = y on the laser plane, with pixels at `mm_per_px` (a straight
    image row: only the spacing matters to the segment builder)."""
    x = np.arange(x0, x1, step_mm)
    pts = np.stack([x, np.full_like(x, y), np.full_like(x, -900.0)], axis=1)
    px = np.stack([x / mm_per_px, np.full_like(x, 100.0)], axis=1)
    return pts, px


def test_dashes_of_one_stripe_make_one_segment() -> None:
    """A stripe seen 4 px apart (11 mm at 2.8 mm/px) whose light drops out for 12 and 28 px
    stretches (as on a dark face): without the pixels every dash is too short and dropped;
    with them it is one segment."""
    calib = level_system()
    pts, px = _line(-300.0, 300.0, 1500.0, 11.2, 2.8)
    keep = np.ones(len(pts), bool)
    for a, b in ((5, 7), (11, 13), (17, 23), (28, 30), (34, 36), (41, 43), (47, 49)):
        keep[a:b] = False
    pts, px = pts[keep], px[keep]
    assert segments(pts, calib) == []
    (seg,) = segments(pts, calib, pixels=px)
    assert len(seg.points_S) == keep.sum()
    assert seg.length_mm == pytest.approx(np.ptp(pts[:, 0]), abs=1e-6)


def test_a_jump_in_depth_still_splits() -> None:
    """Two stripes next to each other in the image but 300 mm apart in depth (an occluding
    edge) stay two segments: the gap spans far more than its pixels imply."""
    calib = level_system()
    near, near_px = _line(-300.0, 0.0, 1200.0, 11.2, 2.8)
    far, far_px = _line(12.0, 300.0, 1500.0, 14.0, 3.5)
    far_px[:, 0] += 2.0  # the far stripe starts 3 px after the near one ends
    pts = np.concatenate([near, far])
    px = np.concatenate([near_px, far_px])
    got = segments(pts, calib, pixels=px)
    assert len(got) == 2
    assert sorted(round(s.distance_mm) for s in got) == [1200, 1500]


def _check_map_picture(res: dict, png: Path, image: np.ndarray) -> None:
    """The map's picture at --png: the image with every mapped point drawn in its segment's
    colour (or grey), and a top view whose points wear the same colours."""
    from omnisort_hw.core.overlays import PALETTE

    assert res["overlay_png"] == str(png)
    pic = cv2.imread(str(png))
    h, w = image.shape[:2]
    assert pic.shape[0] == h and pic.shape[1] > w + h
    px = np.round(np.asarray(res["pixels"])).astype(int)
    drawn = pic[px[:, 1], px[:, 0]]
    colours = np.array([*PALETTE, (150, 150, 150)])
    on_palette = np.any(np.all(drawn[:, None, :] == colours[None], axis=2), axis=1)
    assert on_palette.all()
    top = pic[:, w : w + h]
    for i in range(len(res["segments"])):
        assert np.any(np.all(top == PALETTE[i % len(PALETTE)], axis=2)), i


@pytest.mark.reference
def test_map_cli_prints_every_point_with_its_pixel_and_keeps_the_dashed_stripe(
    reference_dir: Path, tmp_path: Path
) -> None:
    """`omnisort map --json --points` on the authors' cube scene, calibrated from their
    two-sided image: one pixel per point, and the faint dashed stripe on the dark face behind
    the cubes (pixels u 1040-1180, v 385-405) is mapped into one long straight segment."""
    from omnisort_hw.core.camera_io import save_camera_json
    from omnisort_hw.evaluation.reference_accuracy import SEPARATION_MM, intrinsics_model
    from tests.cli.test_extrinsics_cli import run_cli as cli

    camera = tmp_path / "camera.json"
    save_camera_json(camera, intrinsics_model(reference_dir))
    system = tmp_path / "system.json"

    cal = cli(
        "extrinsics",
        "calibrate",
        str(reference_dir / "two_sided_target.png"),
        "--camera",
        str(camera),
        "--target",
        "two-sided",
        "--separation",
        str(SEPARATION_MM),
        "--out",
        str(system),
    )
    assert cal.returncode == 0, cal.stderr
    assert (tmp_path / "system_overlay.png").is_file()
    image = str(reference_dir / "mapping_cubes.jpg")
    png = tmp_path / "pictures" / "cubes.png"
    proc = cli("map", image, "--system", str(system), "--json", "--points", "--png", str(png))
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)["result"]
    _check_map_picture(res, png, cv2.imread(image))
    pts, px = np.asarray(res["points_S"]), np.asarray(res["pixels"])
    assert pts.shape == (res["points_on_plane"], 3) and px.shape == (res["points_on_plane"], 2)
    dashed = (px[:, 0] > 1040) & (px[:, 0] < 1180) & (px[:, 1] > 385) & (px[:, 1] < 405)
    # 24 stripe points there; the last point of a dash whose fit window sees nothing past it
    # is trimmed as a stripe end (core.laser_stripe.stripe_interior): 19 are kept
    assert dashed.sum() >= 15
    # the dark face is flat and square to Y: its stripe points lie on one line Y = const
    y = pts[dashed, 1]
    assert np.median(np.abs(y - np.median(y))) < 5.0
    holding = [
        s
        for s in res["segments"]
        if min(s["start_S_mm"][0], s["end_S_mm"][0]) < np.min(pts[dashed, 0])
        and max(s["start_S_mm"][0], s["end_S_mm"][0]) > np.max(pts[dashed, 0])
    ]
    assert len(holding) == 1, res["segments"]
    assert holding[0]["length_mm"] > 500.0
