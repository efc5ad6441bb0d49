"""joint with a measured target description: markers at their measured (staggered) places,
one border imaged higher than the other, blob centroids against imaged rectangles."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.joint import calibrate_joint
from omnisort_hw.core.extrinsics.paper import calibrate_paper
from omnisort_hw.core.target_layout import (
    MarkerSpec,
    TargetLayout,
    WallSpec,
    image_centroid_shift,
)
from tests.core.synthetic_target import Scene, project, two_sided

MODEL = OcamModel.equidistant(1920, 1920, 185.0)
ANGLES = {
    "cam_roll_deg": 3.5,
    "cam_pitch_deg": 1.0,
    "cam_yaw_deg": -2.5,
    "laser_roll_deg": -0.5,
    "laser_pitch_deg": 2.0,
    "laser_distance_mm": 950.0,
}
FOOT = -1250.0  # the scene's floor_z: the walls' foot
# staggered markers (mm along from the near end, above the foot), as on the authors' target
ALONG = {"left": (24.5, 1044.5, 25.5, 1041.1), "right": (21.3, 1041.4, 24.7, 1040.4)}
HEIGHT = {"left": (995.3, 995.1, 62.5, 63.5), "right": (995.1, 995.3, 63.5, 62.5)}
NAMES = ("border_near", "border_far", "floor_near", "floor_far")


def _layout(sc: Scene) -> TargetLayout:
    walls = {
        side: WallSpec(
            sc.border_z - FOOT,
            {n: MarkerSpec(a, h) for n, a, h in zip(NAMES, ALONG[side], HEIGHT[side], strict=True)},
        )
        for side in ("left", "right")
    }
    return TargetLayout("two-sided", sc.separation, walls)


def _features(sc: Scene, right_border_mm: float = 0.0):
    """Noise-free features of the staggered target; the right border imaged `right_border_mm`
    above where it stands (a filtered printed edge)."""
    feats = two_sided(MODEL, sc, noise=0.0)
    for side, xw in (("left", -sc.separation / 2), ("right", sc.separation / 2)):
        pts = np.array(
            [[xw, sc.y_near + a, FOOT + h] for a, h in zip(ALONG[side], HEIGHT[side], strict=True)]
        )
        feats.walls[side].markers_px = dict(zip(NAMES, project(MODEL, sc.R, pts), strict=True))
    if right_border_mm:
        ys = np.linspace(sc.y_near + 30, sc.y_near + sc.length - 30, 120)
        xw = sc.separation / 2
        pts = np.stack(
            [np.full_like(ys, xw), ys, np.full_like(ys, sc.border_z + right_border_mm)], 1
        )
        feats.walls["right"].border_px = project(MODEL, sc.R, pts)
    return feats


def _errors(calib) -> dict[str, float]:
    p = calib.parameters()
    return {k: abs(p[k] - v) for k, v in ANGLES.items()}


SCENE = Scene(ANGLES, separation=1292.4, length=1065.9, border_z=-282.4, y_near=403.3)


def test_described_markers_remove_the_stagger_bias() -> None:
    feats = _features(SCENE)
    described = _errors(calibrate_joint(feats, MODEL, SCENE.separation, _layout(SCENE)))
    symmetric = _errors(calibrate_joint(feats, MODEL, SCENE.separation))
    # noise-free: what is left is the solver's tolerance
    assert max(v for k, v in described.items() if k.endswith("_deg")) < 2e-3, described
    assert described["laser_distance_mm"] < 0.05
    # a 3 mm stagger over 1292 mm assumed away tilts the walls' frame by ~0.1 deg
    assert max(v for k, v in symmetric.items() if k.endswith("_deg")) > 0.02, symmetric


def test_a_border_imaged_off_its_height_does_not_tilt_the_described_fit() -> None:
    # 1 mm over the 1292 mm separation is 0.044 deg about the wall direction
    feats = _features(SCENE, right_border_mm=1.0)
    described = _errors(calibrate_joint(feats, MODEL, SCENE.separation, _layout(SCENE)))
    assert described["cam_pitch_deg"] < 2e-3 and described["laser_pitch_deg"] < 2e-3, described


def test_paper_lines_up_the_described_ends() -> None:
    feats = _features(SCENE)
    described = _errors(calibrate_paper(feats, MODEL, SCENE.separation, _layout(SCENE)))
    symmetric = _errors(calibrate_paper(feats, MODEL, SCENE.separation))
    assert described["cam_pitch_deg"] < 0.5 * symmetric["cam_pitch_deg"], (described, symmetric)


@pytest.mark.parametrize("size", [1.0, 50.0])
def test_centroid_shift_against_dense_sampling(size: float) -> None:
    R = SCENE.R
    centre = np.array([[-646.2, 500.0, -300.0]])
    sizes = np.array([[size, size]])
    shift = image_centroid_shift(MODEL, R, centre, sizes)[0]
    s, t = np.meshgrid(np.linspace(-0.5, 0.5, 201), np.linspace(-0.5, 0.5, 201))
    pts = centre + np.stack([np.zeros(s.size), s.ravel() * size, t.ravel() * size], 1)
    uv = project(MODEL, R, pts)
    # dense sampling of the wall is uniform in the wall, not in the image: weight each sample
    # by its image area (the local Jacobian), from neighbouring samples
    grid = uv.reshape(201, 201, 2)
    du = np.gradient(grid, axis=1)
    dv = np.gradient(grid, axis=0)
    area = np.abs(du[..., 0] * dv[..., 1] - du[..., 1] * dv[..., 0]).ravel()
    dense = (uv * area[:, None]).sum(0) / area.sum() - project(MODEL, R, centre)[0]
    assert np.allclose(shift, dense, atol=0.01), (shift, dense)
    if size == 1.0:
        assert np.abs(shift).max() < 1e-3
