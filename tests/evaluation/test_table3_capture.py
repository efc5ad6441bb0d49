"""Table 3 with captures: the clean reference is the clean dataset's own bytes (one render
serves the captures and the clean figures), and kept captures measure again to the same
errors (a change to the extraction is measured without exposing again)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.evaluation.table3_capture import _measure, evaluate_captures, evaluate_kept
from sim_backend.dataset import TABLE3_SCENES, table3_configs
from sim_backend.scene import load_scene, sized, with_camera_effects
from sim_backend.scene_images import render_scene

WIDTH = 480  # small: the comparison is exact, not statistical


def test_the_clean_reference_is_the_rendered_datasets_image() -> None:
    cfg = table3_configs(2, 0)[1]
    k, name = 0, TABLE3_SCENES[0]
    base = sized(load_scene(name), WIDTH).replace(render={"tone_curve": "srgb"})
    seed = cfg.index * 7 + k  # the dataset's image seed for seed 0
    want, want_truth = render_scene(cfg.apply(base), seed=seed, degraded=False)
    _, truth, clean = _measure(cfg.apply(base), seed, CaptureSettings(frames=2))
    assert want_truth is not None
    np.testing.assert_array_equal(clean, want)
    assert truth["camera_rotation"] == want_truth["camera_rotation"]
    assert truth["laser_plane"] == want_truth["laser_plane"]


def test_kept_captures_measure_again_to_the_same_errors(tmp_path: Path) -> None:
    first = evaluate_captures(1, 0, 4, 960, progress=False, keep=tmp_path)
    assert any(m["n"] == 1 for m in first["methods"].values())  # captured and calibrated
    again = evaluate_kept(tmp_path, first["configs"], 4, progress=False)
    for part in ("methods", "clean"):
        a = first[part]["methods"] if part == "clean" else first["methods"]
        b = again[part]["methods"] if part == "clean" else again["methods"]
        assert a.keys() == b.keys()
        for method in a:
            assert a[method]["failures"] == b[method]["failures"]
            if "mae" in a[method]:
                assert a[method]["mae"] == b[method]["mae"], method
    assert first["capture"] == again["capture"]


def test_captures_through_the_colour_camera_keep_the_clean_reference() -> None:
    """`effects`: the frames are exposed through the colour camera's effects, the clean
    reference is the same render's (`scene.with_camera_effects` changes the sensor only)."""
    cfg = table3_configs(2, 0)[1]
    base = sized(load_scene(TABLE3_SCENES[0]), WIDTH).replace(render={"tone_curve": "srgb"})
    settings = CaptureSettings(frames=2)
    plain, _, clean = _measure(cfg.apply(base), 7, settings)
    coloured, _, clean_fx = _measure(with_camera_effects(cfg.apply(base)), 7, settings)
    np.testing.assert_array_equal(clean, clean_fx)
    assert plain.board_image is not None and coloured.board_image is not None
    assert np.abs(plain.board_image.astype(float) - coloured.board_image).mean() > 1.0
    result = evaluate_captures(1, 0, 2, WIDTH, progress=False, effects=True)
    assert result["effects"] is True and result["done"] == 1
