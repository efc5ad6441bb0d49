"""The colour camera's effects (`sim_backend.camera_effects`), each on a picture whose answer is
known: the mosaic keeps flat colours and fringes sharp edges only, the lateral aberration moves
red and blue by the asked shift at the corner, the bloom keeps the light and spreads the asked
share, and through the sensor the crosstalk clips a bright red line to white at its core with
red flanks, as on the real photographs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sim_backend.camera_effects import (
    LASER_LEAK,
    EffectParams,
    bayer,
    bloom,
    draw_effects,
    lateral_chromatic,
)
from sim_backend.scene import DegradeSpec, LaserSpec
from sim_backend.sensor import Exposure, OpticalImage, SensorParams, expose
from tests.sim.test_sensor import PARAMS as SENSOR_TEST_PARAMS


def test_the_mosaic_keeps_flat_colours_and_fringes_only_sharp_edges() -> None:
    img = np.zeros((64, 64, 3), np.uint8)
    img[:, :32] = (40, 160, 220)  # BGR: a flat orange
    img[:, 32:] = (255, 255, 255)  # white; a sharp vertical edge at u = 32
    out = bayer(img).astype(int)
    # Inside flat areas (2 px from the edge and the border) the colour is kept exactly:
    # the interpolation of a constant is the constant.
    assert np.array_equal(out[2:-2, 2:30], img[2:-2, 2:30].astype(int))
    assert np.array_equal(out[2:-2, 34:-2], img[2:-2, 34:-2].astype(int))
    # At the edge, the interpolated channels mix both sides: colours no side has, one or two
    # columns wide (bilinear reaches one pixel).
    wrong = np.abs(out[2:-2] - img[2:-2].astype(int)).max(axis=2) > 8
    cols = np.flatnonzero(wrong.any(axis=0))
    assert cols.size > 0 and set(cols) <= {30, 31, 32, 33}, cols


def test_lateral_chromatic_aberration_moves_red_out_and_blue_in_at_the_corner() -> None:
    h = w = 201
    rgb = np.zeros((h, w, 3), np.float32)
    # a small bright spot on the diagonal, at 0.8 of the way to the corner
    c = 100.0
    p = c + 0.8 * (200.0 - c)
    yy, xx = np.mgrid[0:h, 0:w]
    spot = np.exp(-((xx - p) ** 2 + (yy - p) ** 2) / (2 * 2.0**2)).astype(np.float32)
    rgb[...] = spot[..., None]
    out = lateral_chromatic(rgb, (2.0, -3.0))

    def radial(ch: int) -> float:
        wts = out[..., ch]
        cx = float((wts * xx).sum() / wts.sum())
        cy = float((wts * yy).sum() / wts.sum())
        return float(np.hypot(cx - c, cy - c))

    r0 = float(np.hypot(p - c, p - c))
    corner = float(np.hypot(c, c))
    # shift at radius r: shift_corner * r / corner (a change of magnification)
    assert radial(1) == pytest.approx(r0, abs=0.01)
    assert radial(0) - r0 == pytest.approx(2.0 * r0 / corner, abs=0.05)
    assert radial(2) - r0 == pytest.approx(-3.0 * r0 / corner, abs=0.05)


def test_bloom_keeps_the_light_and_spreads_the_asked_share() -> None:
    rgb = np.zeros((1, 401, 3), np.float32)
    rgb[0, 200] = 100.0
    out = bloom(np.repeat(rgb, 5, axis=0), 0.05, 10.0)[2]
    assert float(out[:, 0].sum()) == pytest.approx(100.0, rel=1e-4)
    assert float(out[200, 0]) == pytest.approx(95.0 + 5.0 / np.sqrt(2 * np.pi * 100), rel=1e-3)
    # the halo 20 px off: the share's Gaussian there (a 1D line blurred in 2D stays 1D)
    g20 = 5.0 * np.exp(-(20.0**2) / 200.0) / np.sqrt(2 * np.pi * 100)
    assert float(out[220, 0]) == pytest.approx(g20, rel=1e-3)


def test_the_leak_follows_the_lasers_colour() -> None:
    rng = np.random.default_rng(0)
    for rgb, main in (((1.0, 0.06, 0.04), 0), ((0.05, 1.0, 0.1), 1), ((0.1, 0.2, 1.0), 2)):
        fx = draw_effects(rgb, ((0.15, 0.35), (-0.1, 0.75)), (0.05, 0.15), (14.0, 24.0), True, rng)
        assert fx.laser_leak[main] == rgb[main]
        for ch, (lo, hi) in LASER_LEAK[main].items():
            assert max(lo, rgb[ch]) <= fx.laser_leak[ch] <= max(hi, rgb[ch]), (rgb, fx)
        assert 0.15 <= fx.chromatic_px[0] <= 0.35 and -0.1 <= fx.chromatic_px[1] <= 0.75
        assert 0.05 <= fx.bloom <= 0.15 and 14.0 <= fx.bloom_sigma_px <= 24.0


PARAMS = replace(SENSOR_TEST_PARAMS, blur_sigma_px=1.0, jpeg_quality=90)
FX = EffectParams(
    laser_leak=(1.0, 0.1, 0.4), chromatic_px=(0.0, 0.0), bloom=0.0, bloom_sigma_px=0.0, bayer=False
)


def _line_frame(params: SensorParams) -> np.ndarray:
    """A dark grey card crossed by a bright red laser line (Gaussian, sigma 3 px, 6 times the
    full scale at its centre), through the sensor."""
    size = 96
    base = np.full((size, size, 3), 0.1, np.float32)
    v = np.arange(size, dtype=np.float32)[:, None]
    laser = np.repeat(6.0 * np.exp(-0.5 * ((v - 48.0) / 3.0) ** 2), size, axis=1)
    opt = OpticalImage.prepare(base, laser, LaserSpec(), params, np.random.default_rng(0))
    settings = Exposure(pixel_format="BGR3")
    return expose(opt, params, settings, np.random.default_rng(1))[0].astype(int)


def test_through_the_sensor_crosstalk_clips_a_bright_red_line_to_white_at_its_core() -> None:
    plain = _line_frame(PARAMS)[:, 48]
    real = _line_frame(replace(PARAMS, effects=FX))[:, 48]
    # Without crosstalk the core stays red: green and blue see only the spec's small share
    # (0.06 and 0.04 of 6 full scales, plus the card's 0.1: under half the scale).
    assert plain[48, 2] == 255 and plain[48, 1] < 128 and plain[48, 0] < 128
    # With it, blue sees 0.4 of the line: 2.4 times full scale at the centre, so it clips too
    # and the core is near white (green at 0.1 x 6 = 0.6 of full scale, plus the card).
    assert real[48, 2] == 255 and real[48, 0] == 255 and real[48, 1] > 150
    # The flanks stay red: red clips first, blue not yet (1.5 full scale of laser light is
    # 0.6 for blue), about 4 px off the centre.
    flank = real[43]
    assert flank[2] == 255 and flank[0] < 230, flank


def test_a_scene_asks_for_the_effects_and_the_other_draws_stay() -> None:
    spec = DegradeSpec(enabled=True)
    plain = SensorParams.draw(spec, np.random.default_rng(7))
    with_fx = SensorParams.draw(replace(spec, effects=True), np.random.default_rng(7))
    assert plain.effects is None and with_fx.effects is not None
    assert replace(with_fx, effects=None) == plain
    assert "effects" not in plain.to_dict() and with_fx.to_dict()["effects"]["bayer"] is True


def test_a_degraded_render_gets_the_same_effects() -> None:
    """The renders' "real camera" (`degrade`) with the effects: the core of a bright red line
    clips to white, and the mosaic fringes the card's edge."""
    from sim_backend.degrade import DegradeParams, degrade

    size = 96
    base = np.full((size, size, 3), 0.1, np.float32)
    base[:, 60:] = 0.8  # a light card right of u = 60: a sharp edge
    v = np.arange(size, dtype=np.float32)[:, None]
    laser = np.repeat(6.0 * np.exp(-0.5 * ((v - 30.0) / 3.0) ** 2), size, axis=1)
    params = DegradeParams.draw(
        DegradeSpec(
            enabled=True,
            effects=True,
            noise_read=(0.0, 0.0),
            noise_shot=(0.0, 0.0),
            blur_sigma_px=(0.0, 0.0),
            vignetting=(0.0, 0.0),
            exposure_ev=(0.0, 0.0),
            gamma=(1.0, 1.0),
            jpeg_quality=(100, 100),
            ambient=(0.0, 0.0),
            laser_uneven=(0.0, 0.0),
            laser_speckle=(0.0, 0.0),
            chromatic_red_px=(0.0, 0.0),
            chromatic_blue_px=(0.0, 0.0),
            bloom=(0.0, 0.0),
        ),
        np.random.default_rng(3),
        LaserSpec().color.rgb,
    )
    assert params.effects is not None and params.effects.laser_leak[2] >= 0.2
    img = degrade(base, laser, LaserSpec(), params, np.random.default_rng(4)).astype(int)
    core = img[30, 20]
    assert core[2] >= 250 and core[0] >= 250, core  # red and blue clipped: white-ish
    # the edge at u = 60 far from the line: colour fringes beside it, none on flat card
    rows = img[60:90]
    chroma = np.abs(rows[..., 2] - rows[..., 1]) + np.abs(rows[..., 0] - rows[..., 1])
    assert chroma[:, 58:62].max() > 20 and chroma[:, 40:55].max() <= 6, chroma.max(axis=0)
