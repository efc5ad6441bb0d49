"""Accuracy on the authors' Unity renders against the settings they published (issue: accuracy
on pictures we did not make). Skips with the reason when ../shared/reference is absent.

The goals are the issue's. Those not met yet are strict xfails that name what remains and
why (attribution in the README): they fail loudly the day they start to pass.
"""

from __future__ import annotations

from pathlib import Path

import pytest

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

pytestmark = pytest.mark.reference

_INTRINSICS_SPREAD_DEG = 0.02  # camera roll's jackknife half-range over the nine views
_INTRINSICS = "intrinsics from a1..a9 move camera roll by +-0.02 deg (jackknife)"
_SCENE = (
    "with the authors' own camera and laser the laser lines put the walls 1288.5 mm apart, not "
    "1292.4 (laser distance +3 mm on every wall method)"
)
_PITCH = "camera/laser pitch: the borders stand 1.0 mm apart in height under the authors' camera"
_LASER = (
    "the authors' laser is not one plane on their flat walls: with their camera and laser the "
    "left wall's stripe slopes -1.07 deg on its near half and -0.11 deg on its far half (their "
    "plane: -0.50 deg)"
)


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
        pytest.param(
            "joint",
            0.03,
            1.5,
            marks=pytest.mark.xfail(strict=True, reason=f"{_SCENE}; {_PITCH}; {_LASER}"),
        ),
        pytest.param(
            "joint_three_sided",
            0.03,
            1.5,
            marks=pytest.mark.xfail(strict=True, reason=f"{_SCENE}; {_PITCH}; {_LASER}"),
        ),
        pytest.param(
            "paper",
            0.06,
            3.0,
            marks=pytest.mark.xfail(strict=True, reason=f"{_SCENE}; {_PITCH}; {_LASER}"),
        ),
        pytest.param(
            "method1",
            0.06,
            3.0,
            marks=pytest.mark.xfail(strict=True, reason=f"{_SCENE}; {_PITCH}; {_LASER}"),
        ),
        pytest.param(
            "method2",
            0.1,
            3.0,
            marks=pytest.mark.xfail(
                strict=True, reason=f"camera roll -0.14 deg on the checkerboards; {_INTRINSICS}"
            ),
        ),
    ],
)
def test_each_method_against_the_authors_settings(
    after: dict[str, ReferenceRun], row: str, max_deg: float, max_mm: float
) -> None:
    angle, distance = worst(after, row)
    assert angle <= max_deg and distance <= max_mm, (row, after[row].errors)


@pytest.mark.xfail(
    strict=True,
    reason=f"{_PITCH}; {_LASER}; the three-sided target's far wall is 0.08 deg off square",
)
def test_two_sided_and_three_sided_joint_agree(after: dict[str, ReferenceRun]) -> None:
    diff = cross_target(after)
    assert all(abs(v) <= 0.03 for k, v in diff.items() if k.endswith("_deg")), diff


def test_every_method_stays_within_the_published_method_s_accuracy(
    after: dict[str, ReferenceRun],
) -> None:
    """A floor that must hold today: every angle of every method within 0.15 deg (the published
    Table 3 errors are 0.05-0.29 deg) and every method's laser distance within 5 mm (method2's,
    scaled by the boards' squares instead of the walls' separation, is within 0.01 mm)."""
    for row, run in after.items():
        angle, distance = worst(after, row)
        assert angle < 0.15, (row, run.errors)
        assert distance < 5.0, (row, run.errors)


def test_the_images_disagree_with_the_published_scene(
    reference_dir: Path, model: OcamModel
) -> None:
    """The evidence the unmet goals rest on (docs/calibration.md), on both target images. With
    the authors' own camera and laser taken as true: the side walls' laser lines stand ~1288.5
    mm apart, not the stated 1292.4 (0.3 %, +2.9 mm of laser distance on any method scaled by
    the walls; the boards' 116 mm squares give 950.0 mm); and the left wall's stripe bends by
    ~0.9 deg of slope between its near and far halves, where one plane meets a flat wall in a
    straight line (the halves' slopes are known to ~0.03 deg from ~40 points at 0.2 px)."""
    check = scene_check(reference_dir, model)
    for kind in ("two-sided", "three-sided"):
        e = check[kind]
        assert 1292.4 - e["separation_mm"] > 2.5, (kind, e["separation_mm"])
        slopes = e["laser_slope_deg"]
        assert abs(slopes["left_near_half"] - slopes["left_far_half"]) > 0.5, (kind, slopes)
