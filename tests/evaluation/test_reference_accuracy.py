"""Accuracy on the authors' Unity renders against their exact scene (scene_truth.json: the
published angles, the rendered stripe's 953.5 mm), the wall targets as the scene's target
description gives them (issue: accuracy against the exact scene). Skips with the reason when
../shared/reference is absent.

The goals are the issue's. Those not met yet are strict xfails that name what remains and
why (docs/calibration.md): they fail loudly the day they start to pass.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.config.target import load_target_description
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.evaluation.reference_accuracy import (
    ReferenceRun,
    cross_target,
    intrinsics_model,
    run_reference,
    scene_check,
    worst,
)
from omnisort_hw.evaluation.reference_scene import feature_offsets, load_scene

pytestmark = pytest.mark.reference

_INTRINSICS_SPREAD_DEG = 0.02  # camera roll's jackknife half-range over the nine views
_FAR_BORDER = (
    "the far wall's border is imaged tilted 0.1 deg along X (texture filtering; the scene's is "
    "level), and method1 and joint on the three-sided target take it as level: camera pitch "
    "+0.08..+0.10 deg follows"
)
_BAND = (
    "the stripe is drawn as a band a few mm below the true line whose offset ramps by 6 mm "
    "along the left wall's front cube face and changes at the face edge (no steps to undo "
    "there); paper's laser pitch rests on the laser ends' positions along the walls, 0.1 deg "
    "per mm"
)
_BOARDS = "camera roll -0.13 deg on the checkerboards (not investigated in this issue)"


@pytest.fixture(scope="module")
def model(reference_dir: Path) -> OcamModel:
    return intrinsics_model(reference_dir)


@pytest.fixture(scope="module")
def after(reference_dir: Path, model: OcamModel) -> dict[str, ReferenceRun]:
    return run_reference(reference_dir, model, SRGB)


@pytest.fixture(scope="module")
def before(reference_dir: Path, model: OcamModel) -> dict[str, ReferenceRun]:
    return run_reference(reference_dir, model, ToneCurve.identity())


def test_the_tone_curve_removes_most_of_the_shared_camera_roll_bias(
    before: dict[str, ReferenceRun], after: dict[str, ReferenceRun]
) -> None:
    """Every wall method shares a camera-roll bias (-0.060 to -0.077 deg, depending on the
    intrinsics' refinement) well beyond the intrinsics' own spread (+-0.02 deg, jackknife over
    a1..a9); undoing the sRGB curve before the borders are located removes more than half of it
    on each, and what is left sits within that spread of 0.03 deg."""
    for row in ("joint", "paper", "method1", "joint_three_sided"):
        was, now = before[row].errors["cam_roll_deg"], after[row].errors["cam_roll_deg"]
        assert was < -2 * _INTRINSICS_SPREAD_DEG, (row, was)
        assert abs(now) < 0.5 * abs(was), (row, was, now)
        assert abs(now) < 0.035, (row, now)


@pytest.mark.parametrize(
    ("row", "max_deg", "max_mm"),
    [
        pytest.param("joint", 0.03, 1.5),
        pytest.param(
            "joint_three_sided",
            0.03,
            1.5,
            marks=pytest.mark.xfail(strict=True, reason=_FAR_BORDER),
        ),
        pytest.param("paper", 0.06, 3.0, marks=pytest.mark.xfail(strict=True, reason=_BAND)),
        pytest.param(
            "method1", 0.06, 3.0, marks=pytest.mark.xfail(strict=True, reason=_FAR_BORDER)
        ),
        pytest.param("method2", 0.1, 3.0, marks=pytest.mark.xfail(strict=True, reason=_BOARDS)),
    ],
)
def test_each_method_against_the_exact_scene(
    after: dict[str, ReferenceRun], row: str, max_deg: float, max_mm: float
) -> None:
    """Every angle within max_deg of the scene, the laser distance within max_mm of the
    rendered stripe's 953.5 mm."""
    angle, distance = worst(after, row)
    assert angle <= max_deg and distance <= max_mm, (row, after[row].errors)


def test_the_described_target_is_what_removes_joint_s_pitch_bias(
    reference_dir: Path, model: OcamModel, after: dict[str, ReferenceRun]
) -> None:
    """With the symmetric paper target assumed, the two-sided image's borders (imaged 1 mm
    apart in height) and markers (staggered 3 mm between the walls) tilt `joint` by more than
    the goal; with the scene's description it is within it (previous test)."""
    symmetric = run_reference(reference_dir, model, SRGB, described=False)
    e = symmetric["joint"].errors
    assert max(abs(e["cam_pitch_deg"]), abs(e["laser_pitch_deg"])) > 0.03, e


@pytest.mark.xfail(strict=True, reason=_FAR_BORDER)
def test_two_sided_and_three_sided_joint_agree(after: dict[str, ReferenceRun]) -> None:
    diff = cross_target(after)
    assert all(abs(v) <= 0.03 for k, v in diff.items() if k.endswith("_deg")), diff


def test_the_reference_runs_use_the_scene_s_description(
    reference_dir: Path, model: OcamModel, tmp_path: Path
) -> None:
    """The wall targets are described by a TOML file written from scene_truth.json and read by
    the product's loader: its markers are the scene's, per wall (mirrored, not one layout)."""
    run_reference(reference_dir, model, SRGB, description_dir=tmp_path)
    scene = load_scene(reference_dir)
    layout = load_target_description(tmp_path / "authors_two_sided_target.toml")
    assert layout.separation_mm == pytest.approx(1292.40, abs=0.01)
    y0 = scene["derived"]["wall_Y_range_mm"][0]
    for wall in ("left", "right"):
        truth = sorted(m["centre_S"][1] - y0 for m in scene["walls"][wall]["markers"].values())
        got = sorted(m.along_mm for m in layout.walls[wall].markers.values())
        assert np.allclose(got, truth, atol=0.006), (wall, got, truth)
    left, right = layout.walls["left"].markers, layout.walls["right"].markers
    assert abs(left["border_near"].along_mm - right["border_near"].along_mm) > 1.0


def test_the_far_wall_stripe_is_parallel_to_the_scene_s_line(reference_dir: Path) -> None:
    """Through the scene's own camera, the far wall's extracted stripe (a staircase of three
    4.8 mm ramps as rendered) runs parallel to the true laser line within 0.02 deg (the band
    lies at one depth on that wall's cube face, so the rendered stripe is parallel too)."""
    far = feature_offsets(reference_dir, {"three_sided_target.png": "three-sided"})
    laser = far["three_sided_target.png"]["far"]["laser"]
    assert abs(laser["slope_deg"]) <= 0.02, laser
    assert laser["rms_about_line_mm"] < 0.5, laser


def test_every_method_stays_within_the_published_method_s_accuracy(
    after: dict[str, ReferenceRun],
) -> None:
    """A floor that must hold today: every angle of every method within 0.15 deg (the published
    Table 3 errors are 0.05-0.29 deg) and every method's laser distance within 5 mm of the
    rendered stripe's."""
    for row, run in after.items():
        angle, distance = worst(after, row)
        assert angle < 0.15, (row, run.errors)
        assert distance < 5.0, (row, run.errors)


def test_the_renderer_s_effects_as_measured(reference_dir: Path, model: OcamModel) -> None:
    """What the renderer puts in the pixels and no method undoes (docs/calibration.md), on both
    target images with the scene's camera and laser taken as true: the stripe's band lies
    below the true line, so the side walls' laser lines put the walls 1288.5 mm apart, not
    1292.4 (+3.5 mm of laser distance); the left wall's stripe bends by ~0.9 deg of slope
    between its halves at the cube-face edge; the borders are imaged ~1 mm apart in height."""
    check = scene_check(reference_dir, model)
    for kind in ("two-sided", "three-sided"):
        e = check[kind]
        assert 1292.4 - e["separation_mm"] > 2.5, (kind, e["separation_mm"])
        slopes = e["laser_slope_deg"]
        assert abs(slopes["left_near_half"] - slopes["left_far_half"]) > 0.5, (kind, slopes)
        heights = e["border_z_mm"]
        assert 0.5 < heights["right"] - heights["left"] < 1.5, (kind, heights)
