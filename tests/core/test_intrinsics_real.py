"""Intrinsics on real photographs (`../shared/reference/real/fisheye2`): detection of every
board, the robust fit, and the report; skipped, with the reason, when the set is absent."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.core.camera_io import load_camera_json
from omnisort_hw.core.checkerboard import (
    BoardSpec,
    detect_board,
    ring_profiles,
    saddle_mask,
    saddle_scores,
)
from omnisort_hw.errors import FeatureNotFoundError

FISHEYE2 = Path(__file__).resolve().parents[2].parent / "shared" / "reference" / "real" / "fisheye2"
BOARD = BoardSpec(8, 6, 117.0)
PEER_RMS_PX = 0.105  # py-OCamCalib on the same 16 photographs (2D RMS)


@pytest.fixture(scope="module")
def photos() -> list[Path]:
    paths = sorted(FISHEYE2.glob("Fisheye2_*.jpg"))
    if len(paths) != 16:
        pytest.skip(f"real fisheye photographs not found at {FISHEYE2}")
    return paths


@pytest.fixture(scope="module")
def cli_run(photos: list[Path], tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("fisheye2") / "camera.json"
    rrd = out.with_name("run.rrd")
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "omnisort_hw.cli",
            "intrinsics",
            "calibrate",
            *map(str, photos),
            "--board",
            "8x6",
            "--square",
            "117",
            "--out",
            str(out),
            "--json",
            "--log",
            str(rrd),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    return {"summary": json.loads(proc.stdout)["result"], "out": out, "rrd": rrd}


@pytest.mark.reference
def test_every_board_is_found_in_grey_and_in_colour(photos: list[Path]) -> None:
    for path in photos:
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found = detect_board(grey, BOARD)
        colour = detect_board(cv2.imread(str(path), cv2.IMREAD_COLOR), BOARD)
        assert np.allclose(found.corners, colour.corners, atol=1e-6), path.name
        assert found.good.sum() >= 46, (path.name, found.rejected)


@pytest.mark.reference
def test_vignetting_and_uneven_light_do_not_lose_the_board(photos: list[Path]) -> None:
    grey = cv2.imread(str(photos[0]), cv2.IMREAD_GRAYSCALE).astype(np.float64)
    h, w = grey.shape
    v, u = np.indices(grey.shape)
    r = np.hypot(u - w / 2, v - h / 2) / (0.5 * np.hypot(w, h))
    gain = (1.0 - 0.7 * r**2) * (0.6 + 0.4 * u / w)  # cos^4-like fall-off and a side light
    dim = np.clip(grey * gain, 0, 255).astype(np.uint8)
    base = detect_board(grey.astype(np.uint8), BOARD).corners
    moved = np.linalg.norm(detect_board(dim, BOARD).corners - base, axis=1)
    # Sub-pixel refinement is invariant to a smooth gain to first order: within the
    # corners' own noise (a few hundredths of a pixel on this set).
    assert np.median(moved) < 0.05 and moved.max() < 0.3


@pytest.mark.reference
def test_a_partial_or_shifted_grid_is_not_taken_for_the_board(photos: list[Path]) -> None:
    """The board has 8x6 inner corners: asked for 8x5 or 7x6, the detector must not return
    part of it (it would shift the board frame by a square). Three views, every other one of
    the first six (each refusal runs every detector the product has, about 2 s)."""
    accepted = 0
    for path in photos[:6:2]:
        grey = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        for size in ((8, 5), (7, 6)):
            try:
                detect_board(grey, size)
                accepted += 1
            except FeatureNotFoundError as exc:
                assert f"{size[0]}x{size[1]}" in str(exc)
    assert accepted == 0


@pytest.mark.reference
def test_the_saddle_check_tells_corners_from_square_middles(photos: list[Path]) -> None:
    grey = cv2.imread(str(photos[1]), cv2.IMREAD_GRAYSCALE)
    corners = detect_board(grey, BOARD).corners
    grid = corners.reshape(6, 8, 2)
    middles = (0.25 * (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:])).reshape(
        -1, 2
    )
    radius = np.full(len(corners), 5.0)
    _, contrast, _ = saddle_scores(ring_profiles(grey, corners, radius))
    ref = float(np.median(contrast))
    assert np.mean(saddle_mask(grey, corners, radius, ref)) > 0.95
    assert not np.any(saddle_mask(grey, middles, radius[: len(middles)], ref))


@pytest.mark.reference
def test_fisheye2_all_images_used_and_rms_below_the_peer(cli_run: dict) -> None:
    s = cli_run["summary"]
    # Fisheye2_1 and Fisheye2_16 are the same file: counted once, and said so.
    assert s["images_used"] == 15 and s["images_rejected"] == []
    assert [(Path(r["file"]).name, Path(r["same_as"]).name) for r in s["repeated_views"]] == [
        ("Fisheye2_16.jpg", "Fisheye2_1.jpg")
    ]
    assert "Fisheye2_16" in s["repeated_views_warning"]
    # Held out, a view is fitted worse than in sample, and not by much (15 views).
    cv = s["cross_validation"]
    assert cv["in_sample_rms_px"] <= cv["rms_px"] < 1.5 * cv["in_sample_rms_px"]
    unc = s["projection_uncertainty"]["median_px_at_angle_deg"]
    assert 0 < unc["45"] < unc["80"]
    picture = cv2.imread(str(cli_run["out"].with_name("camera_uncertainty.png")))
    assert picture is not None and abs(picture.shape[0] - 480) <= 16
    # Few corners dropped (gross errors only), each with its reason (in camera.json; the
    # reply counts them).
    _, meta = load_camera_json(cli_run["out"])
    dropped = meta["corners_rejected"]
    assert s["corners_rejected"] == len(dropped) <= 0.03 * 48 * 15
    assert all(c["reason"] and "file" in c and "corner" in c for c in dropped)
    n = 48 * 15 - len(dropped)
    # The RMS beats py-OCamCalib's by more than its own sampling noise (relative standard
    # deviation of an RMS over n corners in 2D: 1 / sqrt(2 n)).
    assert s["rms_px"] * (1 + 3 / np.sqrt(2 * n)) < PEER_RMS_PX
    # The lens: centre near the middle of the 748x480 frame.
    cu, cv_ = s["model"]["center_uv"]
    assert abs(cu - 373.5) < 30 and abs(cv_ - 239.5) < 30


@pytest.mark.reference
def test_fisheye2_report_png_and_rrd(cli_run: dict) -> None:
    from omnisort_hw.runlog import entity_paths

    s = cli_run["summary"]
    report = Path(s["report"])
    assert report.parent == cli_run["out"].parent and report.suffix == ".png"
    picture = cv2.imread(str(report))
    assert picture is not None and picture.shape[0] > 500
    assert 0.0 <= s["coverage"]["outer_band_covered"] <= 1.0
    # This set's boards leave most of the rim empty: the report must say so.
    assert s["coverage"]["outer_band_covered"] < 0.5 and s["coverage"]["warning"]
    assert "/intrinsics/report" in entity_paths(cli_run["rrd"])
