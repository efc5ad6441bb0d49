"""Map point sigmas: the pixel part against a Monte Carlo of pixel noise, the stripe noise
estimate against injected noise, the extrinsics' part against perturbed calibrations."""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.covariance import ExtrinsicCovariance
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.map_uncertainty import point_sigmas, stripe_pixel_sigma
from omnisort_hw.core.mapping import pixels_to_plane

MODEL = OcamModel.equidistant(1920, 1920, 185.0)
ANGLES = {
    "cam_roll_deg": 2.0,
    "cam_pitch_deg": -3.0,
    "cam_yaw_deg": 1.0,
    "laser_roll_deg": 1.5,
    "laser_pitch_deg": -2.0,
    "laser_distance_mm": 900.0,
}


def _wall_pixels(calib: SystemCalibration, x_wall: float = 700.0, n: int = 300) -> np.ndarray:
    """The laser line on a wall X = x_wall, as pixels."""
    y = np.linspace(-600.0, 900.0, n)
    nrm, d = calib.laser_normal, calib.laser_distance_mm
    z = -d - (nrm[0] * x_wall + nrm[1] * y) / nrm[2]
    pts = np.stack([np.full(n, x_wall), y, z], axis=1)
    return MODEL.ray_to_pixel(pts @ calib.R_SC)


def _across_stripe(px: np.ndarray) -> np.ndarray:
    """(N, 2) unit image directions across a stripe of ordered points, from the neighbours."""
    t = np.gradient(px, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return np.stack([-t[:, 1], t[:, 0]], axis=1)


def test_pixel_part_matches_monte_carlo_across_the_wall() -> None:
    calib = SystemCalibration.from_angles(MODEL, ANGLES, "truth")
    px = _wall_pixels(calib)
    sigma_px = 0.1
    sig = point_sigmas(px, calib, np.full(len(px), sigma_px))
    rng = np.random.default_rng(0)
    # Noise across the stripe only: its image direction from the neighbours.
    across = _across_stripe(px)
    xs = [
        pixels_to_plane(px + across * rng.normal(0, sigma_px, (len(px), 1)), calib)[:, 0]
        for _ in range(400)
    ]
    scatter = np.std(np.array(xs), axis=0)
    inner = slice(5, -5)
    # The wall's normal is X; 400 draws know a std to 3.5 %.
    assert np.allclose(sig.normal_mm[inner], scatter[inner], rtol=0.12)


def test_stripe_noise_is_measured_from_the_stripe() -> None:
    calib = SystemCalibration.from_angles(MODEL, ANGLES, "truth")
    px = _wall_pixels(calib, n=400)
    across = _across_stripe(px)
    noisy = px + across * np.random.default_rng(1).normal(0, 0.05, (len(px), 1))
    est = stripe_pixel_sigma(noisy, np.zeros(len(px), int))
    # 400 points, MAD: about 5 % spread; the largest of four spacings is biased up a little.
    assert 0.045 < float(est[0]) < 0.065


def test_a_structured_error_raises_the_sigma_where_it_is() -> None:
    # A clean stripe (0.03 px white noise) with a wave of +-0.2 px over 24 of its 400 centres,
    # as an albedo edge under the band makes: the chain's robust scatter does not see 6 % of
    # its points, the window around them does.
    calib = SystemCalibration.from_angles(MODEL, ANGLES, "truth")
    px = _wall_pixels(calib, n=400)
    across = _across_stripe(px)
    err = np.random.default_rng(3).normal(0, 0.03, len(px))
    wave = slice(200, 224)
    err[wave] += 0.2 * np.sin(np.arange(24) * 2.0 * np.pi / 12.0)
    est = stripe_pixel_sigma(px + across * err[:, None], np.zeros(len(px), int))
    wave_rms = float(np.sqrt(np.mean(err[wave] ** 2)))
    assert float(np.median(est[wave])) >= 0.5 * wave_rms
    clean = np.r_[20:150, 280:380]
    assert float(np.median(est[clean])) <= 0.045  # within the window estimate's spread of 0.03


def test_extrinsic_part_matches_perturbed_calibrations() -> None:
    calib = SystemCalibration.from_angles(MODEL, ANGLES, "truth")
    px = _wall_pixels(calib)
    cov = np.diag(np.array([0.01, 0.02, 0.01, 0.01, 0.015, 0.0]) ** 2)
    cov[:5, :5] = np.radians(1.0) ** 2 * cov[:5, :5]
    cov[5, 5] = 0.3**2
    calib.covariance = ExtrinsicCovariance(cov).to_json()
    sig = point_sigmas(px, calib, np.full(len(px), 1e-6))
    rng = np.random.default_rng(2)
    base = np.array(list(ANGLES.values()))
    xs = []
    for _ in range(400):
        draw = rng.multivariate_normal(np.zeros(6), cov)
        draw[:5] = np.degrees(draw[:5])
        angles = dict(zip(ANGLES, base + draw, strict=True))
        xs.append(pixels_to_plane(px, SystemCalibration.from_angles(MODEL, angles, "x"))[:, 0])
    scatter = np.std(np.array(xs), axis=0)
    assert np.allclose(sig.normal_mm, scatter, rtol=0.12)
