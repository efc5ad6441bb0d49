"""The overlay pictures: the drawing primitives, and the fitted model drawn on what it fits."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.core import overlays
from omnisort_hw.core.mapping import segments
from omnisort_hw.core.overlays import (
    MODEL_BORDER,
    MODEL_LASER,
    draw_dots,
    draw_map,
    model_lines,
    nice_step,
    segment_labels,
    write_png,
)
from omnisort_hw.pipeline.extrinsics import ExtrinsicsRun
from tests.core.test_laser_map import level_system


def test_dots_are_stamped_in_place_clipped_and_per_point_coloured() -> None:
    img = np.zeros((20, 30, 3), np.uint8)
    pts = np.array([[5.0, 5.0], [29.4, 19.4], [np.nan, 3.0], [-10.0, -10.0]])
    cols = np.array([[0, 0, 255], [0, 255, 0], [255, 0, 0], [255, 255, 255]], np.uint8)
    out = draw_dots(img, pts, cols, radius=2)
    assert out is img
    assert tuple(img[5, 5]) == (0, 0, 255) and tuple(img[5, 7]) == (0, 0, 255)
    assert tuple(img[5, 8]) == (0, 0, 0)  # radius 2: three pixels off is untouched
    assert tuple(img[19, 29]) == (0, 255, 0)  # at the corner, clipped, no wrap-around
    assert not np.any(img[:, :, 0])  # the NaN and outside points drew nothing


def test_nice_step_and_write_png_roundtrip(tmp_path: Path) -> None:
    assert [nice_step(s) for s in (3000.0, 600.0, 7.0)] == [500.0, 100.0, 2.0]
    img = np.random.default_rng(1).integers(0, 255, (12, 17, 3), dtype=np.uint8)
    path = write_png(tmp_path / "sub" / "x.png", img)
    assert np.array_equal(cv2.imread(str(path)), img)
    assert overlays.overlay_path(tmp_path / "system.json") == tmp_path / "system_overlay.png"


def test_map_picture_colours_each_segment_in_both_panels() -> None:
    """Two straight walls on a level laser plane: the picture is image | top view | legend,
    the image keeps its pixels where no point is, and each segment's points on the image wear
    that segment's colour."""
    calib = level_system(480)
    x = np.linspace(-400.0, 400.0, 60)
    wall_a = np.stack([x, np.full_like(x, 1200.0), np.full_like(x, -900.0)], axis=1)
    wall_b = np.stack([np.full_like(x, 900.0), x + 200.0, np.full_like(x, -900.0)], axis=1)
    pts = np.concatenate([wall_a, wall_b])
    px = calib.model.ray_to_pixel(pts @ calib.R_SC)
    segs = segments(pts, calib, pixels=px)
    assert len(segs) == 2
    labels = segment_labels(pts, segs)
    assert set(labels) == {0, 1} and len(set(labels[:60])) == 1
    image = np.full((480, 480, 3), 90, np.uint8)
    pic = draw_map(image, px, pts, segs, calib, "test")
    assert pic.shape[0] == 480 and pic.shape[1] > 480 + 480
    assert tuple(pic[5, 240]) == (90, 90, 90)  # far from every point: the image as it was
    for i in range(2):
        u, v = np.round(px[labels == i][30]).astype(int)
        assert tuple(pic[v, u]) == overlays.PALETTE[i]
        top = pic[:, 480:960]
        assert np.any(np.all(top == overlays.PALETTE[i], axis=2))


@pytest.fixture(scope="module")
def two_sided(reference_dir: Path) -> tuple[np.ndarray, dict[str, ExtrinsicsRun]]:
    from omnisort_hw.evaluation.reference_accuracy import SEPARATION_MM, intrinsics_model
    from omnisort_hw.pipeline.extrinsics import run_extrinsics
    from omnisort_hw.pipeline.image_files import read_image

    image = read_image(reference_dir / "two_sided_target.png")
    model = intrinsics_model(reference_dir)
    runs = {
        m: run_extrinsics(image, model, "two-sided", m, separation_mm=SEPARATION_MM)
        for m in ("joint", "paper")
    }
    return image, runs


def _distance_px(line: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Distance of each point to the polyline (densely sampled)."""
    t = np.linspace(0.0, 1.0, 20)[:, None, None]
    dense = (line[:-1][None] * (1 - t) + line[1:][None] * t).reshape(-1, 2)
    dense = dense[np.all(np.isfinite(dense), axis=1)]
    return np.min(np.linalg.norm(pts[:, None, :] - dense[None], axis=2), axis=1)


@pytest.mark.reference
@pytest.mark.parametrize("method", ["joint", "paper"])
def test_the_fitted_lines_fall_on_the_detected_ones(
    two_sided: tuple[np.ndarray, dict[str, ExtrinsicsRun]], method: str
) -> None:
    """On the authors' two-sided image, each wall's fitted border and laser line, reprojected
    through the fitted camera, pass through the detected border and stripe points (a wrong
    rotation, a transposed one or a wall on the wrong side is tens of pixels off)."""
    _, runs = two_sided
    run = runs[method]
    lines = model_lines(run.calib, run.features)
    assert {(ln.wall, ln.kind) for ln in lines} == {
        (w, k) for w in ("left", "right") for k in ("border", "laser")
    }
    for ln in lines:
        wall = run.features.walls[ln.wall]
        detected = wall.border_px if ln.kind == "border" else wall.laser_px
        dist = _distance_px(ln.pixels, detected)
        assert np.median(dist) < 1.0 and np.percentile(dist, 95) < 2.5, (ln.wall, ln.kind)


@pytest.mark.reference
def test_the_extrinsics_picture_draws_the_model_over_the_image(
    two_sided: tuple[np.ndarray, dict[str, ExtrinsicsRun]],
) -> None:
    image, runs = two_sided
    run = runs["joint"]
    pic = run.overlay(image, "two_sided_target.png")
    h, w = image.shape[:2]
    assert pic.shape[0] == h and pic.shape[1] > w  # the image, then the legend column
    body = pic[:, :w]
    for ln in model_lines(run.calib, run.features):
        u, v = np.round(ln.pixels[len(ln.pixels) // 2]).astype(int)
        colour = MODEL_BORDER if ln.kind == "border" else MODEL_LASER
        assert tuple(body[v, u]) == colour, (ln.wall, ln.kind)
        assert tuple(image[v, u]) != colour
    # the picture is the image away from what was drawn
    assert np.array_equal(
        body[h - 300 : h - 200, w // 2 - 50 : w // 2 + 50],
        image[h - 300 : h - 200, w // 2 - 50 : w // 2 + 50],
    )
