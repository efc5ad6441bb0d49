"""The simulated camera's sensor: noise per frame, exposure and gain, clipping, flicker, chroma.

Tolerances come from the model's own noise: a standard deviation measured on n pixels is off
by about 1 / sqrt(2 n) of itself, and 6 of those are allowed."""

from __future__ import annotations

import numpy as np
import pytest

from sim_backend.scene import LaserSpec
from sim_backend.sensor import (
    Exposure,
    OpticalImage,
    SensorParams,
    expose,
    flicker_factor,
)

PARAMS = SensorParams(
    full_well_e=4000.0,
    read_noise_e=20.0,
    blur_sigma_px=0.0,
    vignetting=0.0,
    gamma=1.0,
    jpeg_quality=80,
    ambient=0.0,
    ambient_tint=(1.0, 1.0, 1.0),
    laser_uneven=0.0,
    laser_speckle=0.0,
)


def flat(level: float, size: int = 256) -> OpticalImage:
    base = np.full((size, size, 3), level, np.float32)
    laser = np.zeros((size, size), np.float32)
    return OpticalImage.prepare(base, laser, LaserSpec(), PARAMS, np.random.default_rng(0))


def frame(opt: OpticalImage, draw: int, **kw: object) -> np.ndarray:
    settings = Exposure(**{"laser_on": False, "pixel_format": "BGR3", **kw})  # type: ignore[arg-type]
    return expose(opt, PARAMS, settings, np.random.default_rng(draw))[0].astype(float)


def expected_sigma_levels(level: float, exposure_ms: float, gain: float) -> float:
    e = PARAMS.full_well_e * level * exposure_ms / 10.0
    return 255.0 * gain * np.sqrt(e + PARAMS.read_noise_e**2) / PARAMS.full_well_e


def test_every_frame_has_its_own_noise_and_a_seed_repeats_it() -> None:
    opt = flat(0.3)
    a, b, a2 = frame(opt, 1), frame(opt, 2), frame(opt, 1)
    assert np.array_equal(a, a2)
    # independent draws: the difference has sqrt(2) times one frame's noise
    sigma = expected_sigma_levels(0.3, 10.0, 1.0)
    n = a.size
    assert np.std(a - b) == pytest.approx(np.sqrt(2) * sigma, rel=6 / np.sqrt(2 * n) + 0.02)


@pytest.mark.parametrize(("exposure_ms", "gain"), [(2.0, 1.0), (10.0, 1.0), (5.0, 4.0)])
def test_exposure_and_gain_set_signal_and_shot_plus_read_noise(
    exposure_ms: float, gain: float
) -> None:
    level = 0.2
    img = frame(flat(level), 3, exposure_ms=exposure_ms, gain=gain)
    want_mean = 255.0 * level * exposure_ms / 10.0 * gain
    sigma = expected_sigma_levels(level, exposure_ms, gain)
    n = img.size
    assert img.mean() == pytest.approx(want_mean, abs=6 * sigma / np.sqrt(n) + 0.5)
    # 8-bit rounding adds 1/12 level^2 of variance
    assert img.std() == pytest.approx(np.sqrt(sigma**2 + 1 / 12), rel=6 / np.sqrt(2 * n) + 0.02)


def test_light_beyond_full_scale_clips_at_255() -> None:
    img = frame(flat(0.5), 4, exposure_ms=30.0)
    assert (img == 255).mean() > 0.99


def test_flicker_vanishes_over_whole_mains_periods() -> None:
    for phase in np.linspace(0, 2 * np.pi, 7):
        assert flicker_factor(0.4, 10.0, phase) == pytest.approx(1.0, abs=1e-12)
        assert flicker_factor(0.4, 20.0, phase) == pytest.approx(1.0, abs=1e-12)
    swing = [flicker_factor(0.4, 1.0, p) for p in (0.0, np.pi)]
    assert swing[0] - swing[1] == pytest.approx(2 * 0.4 * np.sinc(0.1), rel=1e-9)


def test_only_compressed_frames_subsample_chroma() -> None:
    size = 64
    base = np.full((size, size, 3), 0.3, np.float32)
    laser = np.zeros((size, size), np.float32)
    laser[:, 31] = 1.0  # a one-pixel vertical red line
    params = PARAMS.__class__(**{**PARAMS.__dict__, "read_noise_e": 0.0, "full_well_e": 1e9})
    opt = OpticalImage.prepare(base, laser, LaserSpec(), params, np.random.default_rng(0))

    def redness_profile(fmt: str) -> np.ndarray:
        img = expose(opt, params, Exposure(pixel_format=fmt), np.random.default_rng(0))[0]
        x = img[size // 2].astype(float)
        return x[:, 2] - np.maximum(x[:, 1], x[:, 0])

    full = redness_profile("BGR3")
    assert np.all(np.abs(np.delete(full, 31)) <= 1.0)  # no colour leaves the line's pixel
    yuyv = redness_profile("YUYV")
    assert yuyv[30] > 0.25 * yuyv[31] or yuyv[32] > 0.25 * yuyv[31]  # shared with its pair
    mjpg = redness_profile("MJPG")
    assert np.sum(np.abs(mjpg[[29, 30, 32, 33]])) > 20.0  # 4:2:0 spreads it over the block
