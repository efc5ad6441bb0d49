"""Laser light from on/off frames, the camera's response from two exposures, and echoes.

Synthetic frames with known light: a Gaussian stripe on a scene with a red patch, flicker
between frames and per-frame noise; tolerances follow from the noise."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.laser_difference import (
    FrameStack,
    corrected_tone,
    encode_mean,
    laser_difference,
    response_gamma,
    stack_frames,
)
from omnisort_hw.core.laser_echoes import direct_hits
from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.core.radiometry import ToneCurve

H = W = 240
LIN = ToneCurve.identity()
SIGMA_LIGHT = 0.004  # noise of one frame (linear light)


def scene(red_patch: bool = True) -> np.ndarray:
    """(H, W, 3) BGR linear light: grey, with a saturated red patch crossing the stripe."""
    img = np.full((H, W, 3), 0.3, np.float32)
    if red_patch:
        img[:, 100:140] = (0.03, 0.03, 0.6)
    return img


def stripe(centre: float = 120.3, peak: float = 0.25) -> np.ndarray:
    rows = np.arange(H, dtype=np.float32)[:, None]
    prof = peak * np.exp(-0.5 * ((rows - centre) / 1.2) ** 2) * np.ones((1, W), np.float32)
    out = np.zeros((H, W, 3), np.float32)
    out[..., 2] = prof
    out[..., 1] = out[..., 0] = 0.05 * prof
    return out


def frames(n: int, laser: bool, flicker: float, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        f = 1.0 + flicker * np.cos(rng.uniform(0, 2 * np.pi))
        light = scene() * f + (stripe() if laser else 0.0)
        light = light + SIGMA_LIGHT * rng.standard_normal(light.shape)
        out.append(np.clip(light * 255 + 0.5, 0, 255).astype(np.uint8))
    return out


def test_the_difference_keeps_the_stripe_and_drops_a_flickering_red_patch() -> None:
    on = stack_frames(frames(8, True, 0.3, 1), LIN, "on")
    off = stack_frames(frames(8, False, 0.3, 2), LIN, "off")
    diff = laser_difference(on, off)
    pts = laser_stripe_points(diff.image)
    assert len(pts) > 20
    # every point is on the stripe's row: centre error well under a pixel (noise of 8 frames)
    assert np.max(np.abs(pts[:, 1] - 120.3)) < 0.3
    assert diff.clipped_core_pixels == 0
    # away from the stripe the red patch and the flicker leave only noise (stripe peak: 200)
    away = diff.image[:100, :, 2].astype(float)
    assert np.percentile(away, 99) < 30


def test_a_clipped_stripe_core_is_counted() -> None:
    on_frames = []
    for img in frames(4, False, 0.0, 3):
        lit = img.astype(np.float32) / 255 + stripe(peak=1.2)
        on_frames.append(np.clip(lit * 255 + 0.5, 0, 255).astype(np.uint8))
    diff = laser_difference(
        stack_frames(on_frames, LIN, "on"), stack_frames(frames(4, False, 0.0, 4), LIN, "off")
    )
    assert diff.clipped_core_pixels > 0
    assert diff.clipped_fraction > 0.1


@pytest.mark.parametrize("gamma", [0.85, 1.0, 1.2])
def test_two_exposures_measure_the_response_deviation(gamma: float) -> None:
    rng = np.random.default_rng(5)
    light = rng.uniform(0.05, 0.45, (H, W, 3)).astype(np.float32)
    srgb = ToneCurve.srgb()

    def shoot(k: float) -> np.ndarray:
        v = np.clip(light * k, 0, 1) ** gamma
        code = np.searchsorted(srgb.light, v).clip(0, 255)
        return code.astype(np.uint8)

    g = response_gamma(
        stack_frames([shoot(1.0)], srgb, "short"),
        stack_frames([shoot(2.0)], srgb, "long"),
        2.0,
        srgb,
    )
    # 8-bit steps of the codes bound the ratio's error; the median over 170k pixels is tight
    assert g == pytest.approx(gamma, abs=0.01)
    assert corrected_tone(srgb, 1.0) is srgb


def test_an_echo_at_the_same_bearing_is_dropped_and_real_depth_edges_are_kept() -> None:
    bearings = np.radians(np.linspace(10, 40, 61))
    wall = np.stack([1000 * np.cos(bearings), 1000 * np.sin(bearings), np.full(61, -800.0)], 1)
    echo = wall[::3] * np.array([0.87, 0.87, 1.0])  # the mirror image maps nearer
    cube = np.stack(  # a cube in front of the wall at other bearings: also a direct hit
        [
            600 * np.cos(np.radians([60, 61, 62])),
            600 * np.sin(np.radians([60, 61, 62])),
            np.full(3, -800.0),
        ],
        1,
    )
    pts = np.concatenate([wall, echo, cube])
    strength = np.concatenate([np.full(61, 100.0), np.full(len(echo), 35.0), np.full(3, 90.0)])
    keep = direct_hits(pts, strength)
    assert keep[:61].all() and keep[-3:].all()
    assert not keep[61:-3].any()


@pytest.mark.parametrize("gamma", [1.0, 1.15])
def test_stacking_and_encoding_are_the_mean_in_light_and_the_nearest_code(gamma: float) -> None:
    """The fast paths (a LUT per frame, a running maximum, a search over midpoints) give
    exactly what their definitions give."""
    tone = corrected_tone(ToneCurve.srgb(), gamma)
    rng = np.random.default_rng(7)
    shots = [rng.integers(0, 256, (31, 17, 3)).astype(np.uint8) for _ in range(5)]
    shots[2][3, 4, 1] = 255
    stack = stack_frames(shots, tone, "test")
    want = np.mean([tone.linearise(f) for f in shots], axis=0, dtype=np.float64)
    np.testing.assert_allclose(stack.mean, want, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(stack.clipped, np.any([(f == 255).any(axis=2) for f in shots], 0))
    light = tone.light.astype(np.float64)
    values = np.concatenate([light, (light[:-1] + light[1:]) / 2, rng.uniform(0, 1, 5000)]).astype(
        np.float32
    )
    codes = encode_mean(FrameStack(values.reshape(1, -1, 1), np.zeros((1, 1), bool), 1), tone)
    dist = np.abs(light[None, :] - values.astype(np.float64)[:, None])
    nearest = np.argmin(dist, axis=1)  # the first (lower) code on a tie
    np.testing.assert_array_equal(codes.ravel(), nearest)
