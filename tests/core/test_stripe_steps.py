"""A stepped (aliased) stripe is put back on the line through its risers' midpoints; smooth,
noisy or kinked stripes are left as they are."""

from __future__ import annotations

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.great_circles import _unit, pixel_scale
from omnisort_hw.core.stripe_steps import unstep_stripe

MODEL = OcamModel.equidistant(1920, 1920, 185.0)


def _line(n: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """Rays (camera frame) along a straight 3D line on a far wall, and its great circle."""
    x = np.linspace(-500.0, 700.0, n)
    pts = np.stack([x, 0.4 * x * 0.01 - 300.0, np.full(n, 1400.0)], axis=1)
    rays = _unit(pts)
    normal = _unit(np.cross(rays[0], rays[-1]))
    return rays, normal


def _moved(rays: np.ndarray, normal: np.ndarray, across_px: np.ndarray) -> np.ndarray:
    scale = pixel_scale(MODEL, rays)
    return MODEL.ray_to_pixel(_unit(rays + (across_px / scale)[:, None] * normal[None, :]))


def _across(uv: np.ndarray, normal: np.ndarray) -> np.ndarray:
    rays = MODEL.pixel_to_ray(uv)
    return (rays @ normal) * pixel_scale(MODEL, rays)


def test_a_staircase_is_put_on_its_risers_line() -> None:
    rays, normal = _line()
    k = np.arange(len(rays))
    step_px, period = 2.0, 37.3  # a fractional number of ramps over the stripe
    saw = step_px * (0.5 - ((k + 11.0) / period) % 1.0)  # ramps down, jumps one step up
    stepped = _moved(rays, normal, saw)
    raw_slope = np.polyfit(k, _across(stepped, normal), 1)[0]
    fixed = _across(unstep_stripe(MODEL, stepped, normal), normal)
    assert abs(raw_slope) * len(k) > 0.1  # the raw centres' line is tilted
    # what is left: the ramps are straight in k, not quite along the fisheye's arc
    assert np.abs(fixed).max() < 0.1, np.abs(fixed).max()
    assert abs(np.polyfit(k, fixed, 1)[0]) * len(k) < 0.05


def test_a_noisy_staircase_keeps_its_noise() -> None:
    rays, normal = _line()
    rng = np.random.default_rng(3)
    k = np.arange(len(rays))
    noise = rng.normal(0.0, 0.05, len(k))
    saw = 2.0 * (0.5 - ((k + 5.0) / 41.0) % 1.0)
    fixed = _across(unstep_stripe(MODEL, _moved(rays, normal, saw + noise), normal), normal)
    # about the risers' line, the points scatter as the noise did (less its fitted part)
    assert 0.5 * noise.std() < fixed.std() < 1.5 * noise.std(), (fixed.std(), noise.std())
    assert abs(fixed.mean()) < 0.05


def test_smooth_noisy_and_kinked_stripes_are_left_alone() -> None:
    rays, normal = _line()
    rng = np.random.default_rng(0)
    k = np.arange(len(rays), dtype=float)
    cases = {
        "smooth": np.zeros(len(k)),
        "noisy": rng.normal(0.0, 0.2, len(k)),
        "kink": np.where(k > 60, 0.05 * (k - 60), 0.0),
        "one jump": np.where(k > 60, 1.5, 0.0),
        "two jumps of opposite sign": np.where((k > 40) & (k < 80), 1.5, 0.0),
        # two steps of one sign three points apart near an end (JPEG on a degraded stripe):
        # the run between them would have to ramp a whole step in three points
        "two close jumps of one sign": np.where(k > 9, 0.8, 0.0) + np.where(k > 12, 0.9, 0.0),
    }
    for name, across in cases.items():
        uv = _moved(rays, normal, across)
        assert np.array_equal(unstep_stripe(MODEL, uv, normal), uv), name
