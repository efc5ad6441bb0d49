"""The extrinsics' covariance: the image noise's part and the intrinsics' modes, against the
scatter of repeated calibrations."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from omnisort_hw.core.extrinsics.covariance import ExtrinsicCovariance
from omnisort_hw.core.extrinsics.joint import calibrate_joint
from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS
from omnisort_hw.core.intrinsics import calibrate
from omnisort_hw.core.intrinsics_uncertainty import model_from_vector, model_uncertainty
from tests.core.synthetic_target import Scene, random_angles, two_sided
from tests.core.test_intrinsics import synthetic_views, truth_model

TRIALS = 16  # a standard deviation from 16 samples is known to about 18 %


def _calibrated_model():
    truth = truth_model()
    result = calibrate(synthetic_views(truth, 21), truth.image_size, degree=6)
    return replace(result.model, uncertainty=model_uncertainty(result))


def test_intrinsic_modes_predict_the_scatter_from_intrinsic_errors() -> None:
    """Noise-free target features seen through one lens; the calibration uses that lens'
    model perturbed by draws from its covariance. The scatter of the six parameters matches
    the modes' prediction (a factor 1.6 either way is outside what 16 draws allow)."""
    model = _calibrated_model()
    unc = model.uncertainty
    vec, cov = np.array(unc["parameters"]), np.array(unc["covariance"])
    cov = 0.5 * (cov + cov.T)
    sc = Scene(random_angles(np.random.default_rng(3)))
    features = two_sided(model, sc, seed=0, noise=0.0)
    rng = np.random.default_rng(8)
    got, predicted = [], []
    for _ in range(TRIALS):
        drawn = vec + rng.multivariate_normal(np.zeros(len(vec)), cov, method="eigh")
        m = model_from_vector(drawn, unc["rho_scale"], model.image_size, unc["poly_degree"])
        calib = calibrate_joint(features, replace(m, uncertainty=unc), sc.separation)
        p = calib.parameters()
        got.append([p[k] for k in PARAMETERS])
        c = ExtrinsicCovariance.from_json(calib.covariance)
        predicted.append(np.sqrt(np.diag(c.modes.T @ c.modes)))
    scatter = np.std(np.array(got), axis=0, ddof=1)
    scatter[:5] = np.radians(scatter[:5])
    pred = np.median(np.array(predicted), axis=0)
    ratio = scatter / pred
    assert np.all((ratio > 1 / 1.6) & (ratio < 1.6)), (scatter, pred)


def test_without_intrinsic_covariance_only_the_noise_counts() -> None:
    from omnisort_hw.core.camera_model import OcamModel

    model = OcamModel.equidistant(1920, 1920, 185.0)
    sc = Scene(random_angles(np.random.default_rng(4)))
    calib = calibrate_joint(two_sided(model, sc, seed=1, noise=0.2), model, sc.separation)
    c = ExtrinsicCovariance.from_json(calib.covariance)
    assert c.modes.shape == (0, 6)
    # The noise part is never below the fit's own; with independent noise, as here, the
    # sandwich estimate agrees with the model's, within its spread (8 markers: ~25 %).
    std = c.std()
    for k in PARAMETERS:
        assert calib.std[k] * (1 - 1e-9) <= std[k] < 1.6 * calib.std[k], k


def test_the_intrinsics_covariance_travels_from_camera_json_to_the_map(tmp_path) -> None:
    """camera.json keeps the covariance with the model; the joint fit turns it into one mode
    per intrinsic direction in system.json; the map's sigmas then count it."""
    from omnisort_hw.core.camera_io import load_camera_json, save_camera_json
    from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
    from omnisort_hw.core.map_uncertainty import point_sigmas

    model = _calibrated_model()
    path = save_camera_json(tmp_path / "camera.json", model, rms_px=0.1)
    loaded, meta = load_camera_json(path)
    assert "uncertainty" not in meta and loaded.uncertainty == model.uncertainty
    sc = Scene(random_angles(np.random.default_rng(6)))
    calib = calibrate_joint(two_sided(loaded, sc, seed=2, noise=0.1), loaded, sc.separation)
    again = SystemCalibration.from_json(calib.to_json())
    modes = ExtrinsicCovariance.from_json(again.covariance).modes
    assert modes.shape == (len(model.uncertainty["parameters"]), 6)
    px = np.array([[700.0, 1500.0], [1300.0, 1450.0]])
    with_i = point_sigmas(px, again, np.full(2, 0.05))
    assert "intrinsics (camera.json covariance)" in with_i.sources
    again.model = replace(again.model, uncertainty=None)
    without = point_sigmas(px, again, np.full(2, 0.05))
    assert np.all(with_i.normal_mm >= without.normal_mm * (1 - 1e-9))
