"""The stripe extractor's real-light rules, each on a frame of the simulated sensor with the
colour camera's effect that broke it (`sim_backend.camera_effects`), with a known centre line.

The line: a Gaussian across (sigma 2 px), straight and slightly tilted, on a dark grey card;
2.5 grey levels of read noise. The tolerances come from the extractor's precision on such a
line: a few hundredths of a pixel from the noise, and a tenth from 8-bit rounding and the
profile's truncation (tests/core/test_laser_stripe.py), so 0.3 px is a clear miss."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from omnisort_hw.core.laser_stripe import laser_stripe_points
from sim_backend.camera_effects import EffectParams
from sim_backend.scene import LaserSpec
from sim_backend.sensor import Exposure, OpticalImage, expose
from tests.sim.test_sensor import PARAMS as SENSOR_TEST_PARAMS

SIZE = 240
SIGMA = 2.0
PARAMS = replace(SENSOR_TEST_PARAMS, full_well_e=20000.0, read_noise_e=200.0, jpeg_quality=95)


def centre_v(u: np.ndarray) -> np.ndarray:
    return 100.0 + 0.1 * (u - SIZE / 2)


def frame(peak: float, leak: tuple[float, float, float], card: float = 0.08) -> np.ndarray:
    """The sensor's BGR frame of the line at `peak` full scales, the laser seen as `leak`."""
    fx = EffectParams(leak, (0.0, 0.0), 0.0, 0.0, bayer=False)
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)
    laser = peak * np.exp(-0.5 * ((v - centre_v(u)) / SIGMA) ** 2)
    base = np.full((SIZE, SIZE, 3), card, np.float32)
    params = replace(PARAMS, effects=fx)
    opt = OpticalImage.prepare(base, laser, LaserSpec(), params, np.random.default_rng(0))
    return expose(opt, params, Exposure(pixel_format="BGR3"), np.random.default_rng(1))[0]


def _errors(pts: np.ndarray) -> np.ndarray:
    inside = (pts[:, 0] > 20) & (pts[:, 0] < SIZE - 20)
    return pts[inside, 1] - centre_v(pts[inside, 0])


def test_a_line_the_camera_sees_as_magenta_is_found_once_at_its_centre() -> None:
    """Blue sees a red line at 0.3 to 0.56 of red on the development photographs (crosstalk)
    and green hardly: at the core g << b, which the redness must not punish (only g > b is
    yellow, orange or tan). Before the rule the line came out twice, on its flanks."""
    pts = laser_stripe_points(frame(0.8, (1.0, 0.05, 0.6)))
    err = _errors(pts)
    assert err.size > 150, err.size  # one point per column across the frame's inside
    assert float(np.max(np.abs(err))) < 0.3, np.sort(np.abs(err))[-5:]


def test_a_line_clipped_to_white_is_found_once_at_the_centre_of_its_clipped_run() -> None:
    """Blue sees 0.4 of the line and green 0.1: at 6 full scales the core clips in red and
    blue and reads near white, its redness falls to zero between two red flanks. Before the
    rule the line came out twice, on its flanks, each a few pixels off (8 to 10 px on the
    development photographs)."""
    img = frame(6.0, (1.0, 0.1, 0.4))
    core = img[np.rint(centre_v(np.array([120.0]))).astype(int)[0], 120]
    assert core[2] == 255 and core[0] == 255, core  # the frame has the effect
    pts = laser_stripe_points(img)
    err = _errors(pts)
    assert err.size > 150, err.size
    assert float(np.max(np.abs(err))) < 0.3, np.sort(np.abs(err))[-5:]
    # once: no two points within a pixel along the line
    u = np.sort(pts[:, 0])
    assert float(np.min(np.diff(u))) > 0.5


def test_a_white_glint_without_red_flanks_is_no_core() -> None:
    """A clipped white streak (a glint on metal, white paper in the sun) has no red flanks:
    no stripe there."""
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)
    img = np.full((SIZE, SIZE, 3), 60, np.uint8)
    streak = np.abs(v - centre_v(u)) < 3.0
    img[streak] = 255
    assert laser_stripe_points(img).shape[0] == 0
