"""Extrinsic methods and mapping on synthetic features projected from known geometry."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.joint import calibrate_joint, closed_form, observations
from omnisort_hw.core.extrinsics.method1 import calibrate_method1
from omnisort_hw.core.extrinsics.method2 import calibrate_method2
from omnisort_hw.core.extrinsics.paper import calibrate_paper
from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS, SystemCalibration
from omnisort_hw.core.mapping import pixels_to_plane, segments
from omnisort_hw.core.residual_correlation import correlation_inflation
from omnisort_hw.errors import CalibrationError
from tests.core.synthetic_target import Scene, checkerboards, random_angles, three_sided, two_sided

MODEL = OcamModel.equidistant(1920, 1920, 185.0)
NOISE = 0.2  # px per coordinate on border, laser and floor points; 1.5x on marker centres


def errors(calib: SystemCalibration, truth: dict[str, float]) -> np.ndarray:
    p = calib.parameters()
    return np.array([p[k] - truth[k] for k in PARAMETERS])


def scenes(n: int, seed: int) -> list[Scene]:
    rng = np.random.default_rng(seed)
    return [Scene(random_angles(rng)) for _ in range(n)]


def test_joint_is_exact_without_noise() -> None:
    # The only error left is the lens model's round trip (inv_error_px ~2e-4 px, i.e. about
    # 2e-5 deg at 611 px/rad): the solver's equations match the independent generator.
    floor_deg = np.degrees(10 * MODEL.inv_error_px / 611.0)
    for k, sc in enumerate(scenes(3, seed=11)):
        calib = calibrate_joint(two_sided(MODEL, sc, seed=k, noise=0.0), MODEL, sc.separation)
        err = errors(calib, sc.angles_deg)
        assert np.all(np.abs(err[:5]) < floor_deg) and abs(err[5]) < 0.01
        assert calib.residuals["rms_px"] < 10 * MODEL.inv_error_px


def test_closed_form_start_is_close() -> None:
    sc = scenes(1, seed=4)[0]
    obs = observations(two_sided(MODEL, sc, seed=1, noise=NOISE), MODEL)
    start = closed_form(obs, sc.separation)
    truth = sc.angles_deg
    got = np.degrees(start.x[:5])
    want = [truth[k] for k in PARAMETERS[:5]]
    assert np.max(np.abs(got - want)) < 0.5
    assert abs(start.d - truth["laser_distance_mm"]) < 10


def test_joint_accuracy_and_honest_std() -> None:
    errs, stds = [], []
    for k, sc in enumerate(scenes(12, seed=1)):
        calib = calibrate_joint(two_sided(MODEL, sc, seed=k, noise=NOISE), MODEL, sc.separation)
        errs.append(errors(calib, sc.angles_deg))
        stds.append([calib.std[p] for p in PARAMETERS])
        # Residuals consistent with the injected noise (markers are noisier, few of them).
        assert 0.8 * NOISE < calib.residuals["rms_px"] < 1.3 * NOISE
    errs, stds = np.abs(np.array(errs)), np.array(stds)
    mae = errs.mean(axis=0)
    assert np.all(mae[:5] < 0.03), mae
    assert mae[5] < 1.0
    # The reported standard deviations describe the errors: normalised errors ~ N(0, 1).
    z = errs / stds
    assert np.sqrt(np.mean(z**2)) < 2.0 and np.max(z) < 5.0


def test_joint_beats_the_paper_chain() -> None:
    joint, paper = [], []
    for k, sc in enumerate(scenes(16, seed=2)):
        feats = two_sided(MODEL, sc, seed=k, noise=NOISE)
        joint.append(np.abs(errors(calibrate_joint(feats, MODEL, sc.separation), sc.angles_deg)))
        paper.append(np.abs(errors(calibrate_paper(feats, MODEL, sc.separation), sc.angles_deg)))
    mj, mp = np.mean(joint, axis=0), np.mean(paper, axis=0)
    # Paired on the same features: joint is nowhere worse beyond two standard errors of the
    # mean difference (roll and yaw come from the same border lines in both), and clearly
    # better where the chain is weak: camera pitch and laser pitch.
    diff = np.array(joint) - np.array(paper)
    se = diff.std(axis=0, ddof=1) / np.sqrt(len(diff))
    assert np.all(diff.mean(axis=0) <= 2 * se), (mj, mp)
    assert mj[1] < 0.5 * mp[1] and mj[4] < 0.5 * mp[4], (mj, mp)
    # The chain is of the published order of accuracy: tenths of a degree at worst.
    assert np.all(mp[:5] < 1.0)


def test_baseline_methods_recover_the_geometry() -> None:
    m1, m2 = [], []
    for k, sc in enumerate(scenes(6, seed=3)):
        m1.append(
            np.abs(
                errors(
                    calibrate_method1(
                        three_sided(MODEL, sc, seed=k, noise=NOISE), MODEL, sc.separation
                    ),
                    sc.angles_deg,
                )
            )
        )
        m2.append(
            np.abs(
                errors(
                    calibrate_method2(checkerboards(MODEL, sc, seed=k, noise=NOISE), MODEL),
                    sc.angles_deg,
                )
            )
        )
    assert np.all(np.mean(m1, axis=0)[:5] < 0.05)
    assert np.all(np.mean(m2, axis=0)[:5] < 0.1)
    assert np.mean(m1, axis=0)[5] < 2.0 and np.mean(m2, axis=0)[5] < 3.0


def test_joint_on_the_three_sided_target() -> None:
    # Exact without noise (lens round trip only), and with noise at least as good as method1's
    # closed form on the same features, with honest standard deviations.
    floor_deg = np.degrees(10 * MODEL.inv_error_px / 611.0)
    for k, sc in enumerate(scenes(2, seed=13)):
        calib = calibrate_joint(three_sided(MODEL, sc, seed=k, noise=0.0), MODEL, sc.separation)
        err = errors(calib, sc.angles_deg)
        assert calib.method == "joint" and "far_wall_y_mm" in calib.target
        assert np.all(np.abs(err[:5]) < floor_deg) and abs(err[5]) < 0.01
    joint, m1, z = [], [], []
    for k, sc in enumerate(scenes(12, seed=14)):
        feats = three_sided(MODEL, sc, seed=k, noise=NOISE)
        cj = calibrate_joint(feats, MODEL, sc.separation)
        e = errors(cj, sc.angles_deg)
        joint.append(np.abs(e))
        z.append(e / np.array([cj.std[p] for p in PARAMETERS]))
        m1.append(np.abs(errors(calibrate_method1(feats, MODEL, sc.separation), sc.angles_deg)))
    # Paired on the same features: nowhere worse than method1 beyond two standard errors.
    diff = np.array(joint) - np.array(m1)
    se = diff.std(axis=0, ddof=1) / np.sqrt(len(diff))
    assert np.all(diff.mean(axis=0) <= 2 * se), (np.mean(joint, axis=0), np.mean(m1, axis=0))
    assert np.sqrt(np.mean(np.square(z))) < 2.0


def test_correlation_inflation_counts_shared_pixels() -> None:
    rng = np.random.default_rng(0)
    white = rng.standard_normal(4000)
    assert correlation_inflation(white) == pytest.approx(1.0, abs=0.15)
    # Each point the mean of 4 consecutive independent samples (overlapping fit windows):
    # the variance of a long average grows by 4.
    shared = np.convolve(rng.standard_normal(4003), np.ones(4) / 4, mode="valid")
    assert correlation_inflation(shared) == pytest.approx(4.0, rel=0.15)


def test_missing_marker_is_a_clear_error() -> None:
    sc = scenes(1, seed=5)[0]
    feats = two_sided(MODEL, sc)
    del feats.walls["right"].markers_px["floor_far"]
    with pytest.raises(CalibrationError, match="right wall: marker floor_far missing"):
        calibrate_joint(feats, MODEL, sc.separation)


def test_system_json_round_trip_compares_with_truth_keys() -> None:
    sc = scenes(1, seed=6)[0]
    calib = calibrate_joint(two_sided(MODEL, sc, noise=0.0), MODEL, sc.separation)
    doc = calib.to_json()
    for key in (
        "camera",
        "camera_rotation",
        "laser_plane",
        "target",
        "method",
        "residuals",
        "std",
        "created",
    ):
        assert key in doc
    back = SystemCalibration.from_json(doc)
    assert back.parameters() == pytest.approx(calib.parameters(), abs=1e-9)
    assert doc["camera_rotation"]["roll_deg"] == pytest.approx(
        sc.angles_deg["cam_roll_deg"], abs=1e-4
    )


def wall_laser_pixels(sc: Scene, x_wall: float, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """Laser line on a vertical wall X = x_wall across Y in [-400, 400] (an obstacle)."""
    nrm, d = sc.normal, sc.d
    ys = np.linspace(-400, 400, n)
    z = -d - (nrm[0] * x_wall + nrm[1] * ys) / nrm[2]
    pts = np.stack([np.full_like(ys, x_wall), ys, z], axis=1)
    return MODEL.ray_to_pixel(pts @ sc.R), pts


@pytest.mark.parametrize("distance", [300.0, 700.0, 1100.0, 1500.0])
def test_mapping_distances_with_a_joint_calibration(distance: float) -> None:
    sc = scenes(1, seed=7)[0]
    calib = calibrate_joint(two_sided(MODEL, sc, seed=3, noise=NOISE), MODEL, sc.separation)
    px, _ = wall_laser_pixels(sc, distance)
    px = px + np.random.default_rng(0).normal(0, NOISE, px.shape)
    mapped = pixels_to_plane(px, calib)
    segs = segments(mapped, calib)
    assert len(segs) == 1
    # Nearest horizontal distance from the camera axis: the wall at X = distance.
    assert abs(segs[0].distance_mm - distance) / distance < 0.002
    assert np.median(np.abs(mapped[:, 0] - distance)) / distance < 0.002


def test_mapping_splits_separate_obstacles_and_ignores_rays_away_from_the_plane() -> None:
    sc = Scene(dict.fromkeys(PARAMETERS, 0.0) | {"laser_distance_mm": 900.0})
    truth = SystemCalibration.from_angles(MODEL, sc.angles_deg, "truth")
    a, _ = wall_laser_pixels(sc, 500.0, 200)
    b, _ = wall_laser_pixels(sc, -900.0, 200)
    up = MODEL.ray_to_pixel(np.array([[0.3, 0.0, 0.5]]) @ sc.R)  # points up: never meets it
    stray = MODEL.ray_to_pixel(np.array([[540.0, 0.0, -900.0]]) @ sc.R)  # lone speck
    mapped = pixels_to_plane(np.concatenate([a, b, up, stray]), truth)
    assert np.isnan(mapped[-2]).all()
    segs = segments(mapped, truth)
    assert [round(s.distance_mm) for s in segs] == [500, 900]


def test_joint_rejects_stray_points() -> None:
    sc = scenes(1, seed=8)[0]
    clean = two_sided(MODEL, sc, seed=2, noise=NOISE)
    dirty = two_sided(MODEL, sc, seed=2, noise=NOISE)
    rng = np.random.default_rng(5)
    for wall in dirty.walls.values():  # 8 of 120 laser points are reflections 5-15 px away
        wall.laser_px[rng.choice(len(wall.laser_px), 8, replace=False)] += rng.uniform(5, 15, 2)
    a = errors(calibrate_joint(clean, MODEL, sc.separation), sc.angles_deg)
    b = errors(calibrate_joint(dirty, MODEL, sc.separation), sc.angles_deg)
    # Without rejection 7% outliers at 10 px would move the laser angles by ~0.1 deg.
    assert np.all(np.abs(b[:5] - a[:5]) < 0.01) and abs(b[5] - a[5]) < 0.3


def test_floor_lines_used_when_consistent_and_refused_when_off_the_wall_plane() -> None:
    sc = scenes(1, seed=9)[0]
    feats = two_sided(MODEL, sc, seed=4, noise=NOISE)
    calib = calibrate_joint(feats, MODEL, sc.separation)
    assert calib.residuals["floor_lines"] == "used"
    # A 10 mm plinth on the left wall only: its white face meets the floor off the wall plane
    # (a symmetric offset is absorbed exactly by the floor height and biases nothing).
    shifted = two_sided(MODEL, sc, seed=4, noise=NOISE)
    ys = np.linspace(sc.y_near + 30, sc.y_near + sc.length - 30, 120)
    pts = np.stack(
        [np.full_like(ys, -sc.separation / 2 + 10), ys, np.full_like(ys, sc.floor_z)], axis=1
    )
    shifted.walls["left"].floor_px = MODEL.ray_to_pixel(pts @ sc.R)
    calib = calibrate_joint(shifted, MODEL, sc.separation)
    assert calib.residuals["floor_lines"].startswith("not used")
    # Used, it would put ~0.7 deg into pitch; without it the markers give the usual accuracy.
    assert np.all(np.abs(errors(calib, sc.angles_deg)[:5]) < 0.1)


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        (("camera_rotation", "matrix"), [[float("nan")] * 3] * 3, "camera_rotation.matrix"),
        (("laser_plane", "normal"), [0.0, float("nan"), 1.0], "laser_plane.normal"),
        (("laser_plane", "normal"), [0.0, 0.0, 0.0], "laser_plane.normal"),
        (("laser_plane", "distance_mm"), float("nan"), "laser_plane.distance_mm"),
        (("laser_plane", "distance_mm"), -950.0, "laser_plane.distance_mm"),
        (("camera", "poly"), [float("nan"), 0.0, 1e-4], "'poly'"),
    ],
)
def test_a_corrupt_system_json_names_the_file_and_field(
    tmp_path, path: tuple[str, str], value: object, field: str
) -> None:
    """A system.json whose plane or rotation holds NaN (json reads it) would map every laser
    pixel to NaN millimetres; it is refused with the file and field instead."""
    import json

    from omnisort_hw.core.extrinsics.system_calibration import load_system_json
    from omnisort_hw.errors import CalibrationFileError

    calib = SystemCalibration.from_angles(
        OcamModel.equidistant(640, 640, 185.0), random_angles(np.random.default_rng(0)), "truth"
    )
    data = calib.to_json()
    data[path[0]][path[1]] = value
    file = tmp_path / "system.json"
    file.write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError) as info:
        load_system_json(file)
    assert str(file) in str(info.value) and field in str(info.value), str(info.value)
