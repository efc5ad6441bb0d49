"""Intrinsics' uncertainty: projection sigma against the scatter of repeated calibrations,
cross-validation, repeated views."""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.intrinsics import calibrate
from omnisort_hw.core.intrinsics_uncertainty import (
    cross_validate,
    model_from_vector,
    model_uncertainty,
    perturbed_models,
    pixel_sigmas,
    projection_uncertainty,
    same_board_views,
    unique_images,
)
from tests.core.test_intrinsics import BOARD, NOISE_PX, synthetic_views, truth_model

TRIALS = 8
RAYS_DEG = (0.0, 30.0, 60.0, 85.0)


def _rays() -> np.ndarray:
    a = np.radians(np.array(RAYS_DEG))
    return np.stack([np.sin(a) * np.cos(0.7), np.sin(a) * np.sin(0.7), np.cos(a)], axis=1)


def _views_and_rotations(seed: int) -> tuple[list, list[np.ndarray]]:
    """synthetic_views' views and, replaying its generator, each board's true rotation."""
    from tests.core.test_intrinsics import board_pose

    model = truth_model()
    views = synthetic_views(model, seed)
    rng = np.random.default_rng(seed)
    plan = [
        (0, 0),
        (30, 20),
        (30, 200),
        (50, 100),
        (50, 290),
        (65, 0),
        (65, 150),
        (78, 60),
        (78, 240),
        (82, 320),
        (80, 130),
        (40, 330),
    ]
    rotations = []
    for polar, azimuth in plan:
        distance, tilt, spin = rng.uniform(900, 1400), rng.uniform(-25, 25), rng.uniform(0, 360)
        while True:
            T = board_pose((polar, azimuth), distance, tilt, spin)
            pts = BOARD.object_points() @ T[:3, :3].T + T[:3, 3]
            if np.all(model.angle_from_axis(pts) < np.radians(91.0)):
                break
            polar -= 1.0
        rng.normal(0.0, NOISE_PX, size=(len(pts), 2))
        rotations.append(T[:3, :3])
    return views, rotations


def test_projection_sigma_matches_the_scatter_of_repeated_calibrations() -> None:
    """Predicted sigma (worst direction) against the spread of the projection of fixed rays
    over TRIALS noise seeds, each fit's camera frame aligned to the truth's as the prediction
    defines it (the mean over the boards of R_fit R_true^T). With TRIALS samples a standard
    deviation is known to about 1/sqrt(2 TRIALS) = 25 %: a factor 2 either way is a failure."""
    truth = truth_model()
    rays = _rays()
    q_true = truth.ray_to_pixel(rays)
    errors, predicted = [], []
    for seed in range(100, 100 + TRIALS):
        views, rotations = _views_and_rotations(seed)
        result = calibrate(views, truth.image_size, degree=6, centre=truth.center_uv)
        pairs = zip(views, rotations, strict=True)
        M = np.mean([result.poses[v.name][:3, :3] @ R.T for v, R in pairs], axis=0)
        predicted.append(pixel_sigmas(result, rays))
        errors.append(result.model.ray_to_pixel(rays @ M.T) - q_true)
    errors = np.array(errors)
    scatter = np.sqrt(np.max(np.var(errors, axis=0, ddof=1), axis=1))
    pred = np.median(np.array(predicted), axis=0)
    assert np.all(np.isfinite(pred)) and np.all(pred > 0)
    ratio = scatter[:3] / pred[:3]  # inside the boards' coverage
    assert np.all((ratio > 0.5) & (ratio < 2.0)), (scatter, pred)
    assert pred[3] > pred[1]  # beyond the boards it grows


def test_sigma_scales_with_the_corner_noise_and_grows_off_the_boards() -> None:
    truth = truth_model()
    views = synthetic_views(truth, 7)
    result = calibrate(views, truth.image_size, degree=6)
    unc = projection_uncertainty(result, step_px=64)
    at = unc.at_angles()
    assert at["0"] is not None and at["80"] is not None
    assert at["80"] > at["45"]
    # The residuals give the noise: about NOISE_PX, so sigma is a fraction of it at the centre.
    assert at["0"] < NOISE_PX


def test_cross_validation_is_above_the_in_sample_rms_and_near_the_noise() -> None:
    truth = truth_model()
    result = calibrate(synthetic_views(truth, 3), truth.image_size, degree=6)
    cv = cross_validate(result, BOARD.object_points())
    assert cv.scheme == "leave one view out"
    assert cv.rms_px is not None and cv.rms_px >= result.rms_px
    # 2D RMS of the noise is sqrt(2) NOISE_PX; held out, only a little above (12 views).
    assert cv.rms_px < 1.3 * np.sqrt(2) * NOISE_PX


def test_repeated_views_are_found() -> None:
    img = np.zeros((20, 30), np.uint8)
    other = img.copy()
    other[3, 4] = 1
    kept, repeats = unique_images([("a", img), ("b", other), ("c", img.copy())])
    assert [n for n, _ in kept] == ["a", "b"]
    assert repeats == [{"file": "c", "same_as": "a", "how": "identical pixels"}]
    truth = truth_model()
    views = synthetic_views(truth, 4)
    views.append(type(views[0])("again", views[0].pixels + 0.001, views[0].board))
    result = calibrate(views, truth.image_size, degree=6)
    assert same_board_views(result) == [
        {"file": "again", "same_as": views[0].name, "how": "the same board corners"}
    ]


def test_model_carries_its_covariance() -> None:
    truth = truth_model()
    result = calibrate(synthetic_views(truth, 5), truth.image_size, degree=6)
    unc = model_uncertainty(result)
    again = model_from_vector(
        np.array(unc["parameters"]), unc["rho_scale"], truth.image_size, unc["poly_degree"]
    )
    uv = np.array([[900.0, 1000.0], [300.0, 700.0]])
    assert np.allclose(again.pixel_to_ray(uv), result.model.pixel_to_ray(uv), atol=1e-9)
    from dataclasses import replace

    pairs = perturbed_models(replace(result.model, uncertainty=unc))
    assert len(pairs) == result.n_intrinsic


def test_the_colour_scale_is_fitted_to_the_image_circle() -> None:
    """Beyond the image circle the polynomial is extrapolated and the sigma explodes: scaled by
    all cells, the circle itself was one colour."""
    from omnisort_hw.core.intrinsics_uncertainty import (
        ProjectionUncertainty,
        uncertainty_png,
        uncertainty_top,
    )

    angle = np.linspace(0.0, 110.0, 400)
    sigma = np.where(angle <= 92.5, 0.01 + 0.01 * angle / 92.5, 50.0)
    unc = ProjectionUncertainty(4, np.zeros((400, 2)), sigma, angle, (20, 20), 0.01)
    inside = uncertainty_top(unc, within_deg=92.5)
    assert 0.019 <= inside <= 0.02
    assert uncertainty_top(unc) == 50.0
    img = uncertainty_png(unc, within_deg=92.5)
    colours = {tuple(c) for c in img.reshape(-1, 3)[:: 16 * 4]}
    assert len(colours) > 10  # the circle shows its gradient, not one colour
