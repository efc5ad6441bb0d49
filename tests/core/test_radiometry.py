"""The camera tone curve, and the border-edge bias it causes when it is ignored."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.radiometry import (
    SRGB,
    ToneCurve,
    linear_to_srgb,
    srgb_to_linear,
)
from omnisort_hw.core.target_edges import find_line_edge
from omnisort_hw.core.target_markers import Blob
from omnisort_hw.errors import InputError


def test_srgb_matches_the_standard_and_round_trips() -> None:
    # IEC 61966-2-1: code 0.5 is 21.4 % light, the linear toe ends at 0.04045
    assert srgb_to_linear(np.array(0.5)) == pytest.approx(0.21404, abs=1e-5)
    assert srgb_to_linear(np.array(0.04045)) == pytest.approx(0.04045 / 12.92, rel=1e-5)
    x = np.linspace(0.0, 1.0, 1001)
    assert np.abs(linear_to_srgb(srgb_to_linear(x)) - x).max() < 1e-5
    assert SRGB.light[0] == 0.0 and SRGB.light[255] == 1.0
    assert SRGB.light[128] == pytest.approx(0.2158605, abs=1e-6)


def test_curves_from_names_and_files(tmp_path: Path) -> None:
    assert ToneCurve.parse(None).name == "srgb"
    assert np.allclose(ToneCurve.parse("linear").light, np.arange(256) / 255.0)
    assert ToneCurve.parse("gamma:2.2").light[128] == pytest.approx((128 / 255) ** 2.2, rel=1e-5)
    table = tmp_path / "curve.json"
    table.write_text(json.dumps({"light": [float(v) ** 2 for v in range(256)]}))
    measured = ToneCurve.parse(str(table))
    assert measured.light[255] == 1.0  # any scale is normalised
    assert measured.light[128] == pytest.approx((128 / 255) ** 2, rel=1e-5)
    image = np.full((2, 2, 3), 128, np.uint8)
    assert measured.luminance(image) == pytest.approx(255 * (128 / 255) ** 2, rel=1e-4)


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("gamma:abc", "needs a number"),
        ("gamma:-1", "positive"),
        ("/no/such/curve.json", "not srgb, linear"),
    ],
)
def test_bad_curves_are_named(spec: str, message: str) -> None:
    with pytest.raises(InputError, match=message):
        ToneCurve.parse(spec)


def test_bad_tables_are_refused(tmp_path: Path) -> None:
    short = tmp_path / "short.json"
    short.write_text("[0, 1]")
    with pytest.raises(InputError, match="256"):
        ToneCurve.parse(str(short))
    falling = tmp_path / "falling.json"
    falling.write_text(json.dumps(list(range(255, -1, -1))))
    with pytest.raises(InputError, match="increase"):
        ToneCurve.parse(str(falling))
    with pytest.raises(InputError, match="8-bit"):
        SRGB.linearise(np.zeros((2, 2), np.float32))


def _blurred_step(model: OcamModel, sigma: float, srgb: bool) -> np.ndarray:
    """A vertical dark/bright step through the principal point (a straight 3D line through the
    axis projects onto it), blurred by a Gaussian of `sigma` px in LIGHT, written to 8 bits
    sRGB-encoded (as a camera or renderer writes it) or linear. Bright on the right. Half a
    code of seeded noise before rounding (as sensor noise does) keeps the rounding from
    repeating identically on every row."""
    from math import erf, sqrt

    w, h = model.image_size
    cu = model.center_uv[0]
    frac = np.array([0.5 * (1.0 + erf((x - cu) / (sqrt(2.0) * sigma))) for x in range(w)])
    light = 0.01 + 0.85 * frac
    code = 255.0 * (linear_to_srgb(light) if srgb else light)
    noisy = code[None, :] + np.random.default_rng(1).normal(0.0, 0.5, (h, w))
    img = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
    return np.repeat(img[:, :, None], 3, axis=2)


def _edge_offset(image: np.ndarray, model: OcamModel, tone: ToneCurve) -> float:
    """Mean u of the located edge minus the true edge (the principal point's u), px."""
    cu, cv = model.center_uv
    a, b = Blob(np.array([cu, cv - 150.0]), 30.0), Blob(np.array([cu, cv + 150.0]), 30.0)
    bright = model.pixel_to_ray(np.array([[cu + 60.0, cv]]))[0]
    edge = find_line_edge(tone.luminance(image), model, a, b, bright, "step", [])
    return float(np.mean(edge.points[:, 0]) - cu)


@pytest.mark.parametrize(("sigma", "phase"), [(0.8, 0.3), (1.5, 0.3), (1.5, 0.0)])
def test_ignoring_the_curve_moves_a_blurred_border_and_the_model_removes_it(
    sigma: float, phase: float
) -> None:
    """The mechanism behind the camera-roll bias: on encoded values the gradient peak of a
    blurred step leans to the dark side by a fraction of the blur; undoing the curve gives the
    edge the locator finds on a linear camera's image of the same light (its own sub-pixel
    interpolation error, which depends on the edge's phase, is not the tone curve's)."""
    model = OcamModel.equidistant(480, 480, 185.0, center_uv=(240.0 + phase, 239.5))
    reference = _edge_offset(_blurred_step(model, sigma, srgb=False), model, ToneCurve.identity())
    encoded = _blurred_step(model, sigma, srgb=True)
    modelled = _edge_offset(encoded, model, SRGB)
    ignored = _edge_offset(encoded, model, ToneCurve.identity())
    # what is left is 8-bit rounding and noise, averaged over ~150 edge points
    assert abs(modelled - reference) < 0.01, (modelled, reference)
    # ignored: the edge moves towards the dark side (-u) by a fraction of the blur
    assert ignored - reference < -0.1 * sigma, (ignored, reference)


def test_simulator_writes_srgb_and_mixes_light_linearly() -> None:
    """A flat colour comes out as its encoded value (unchanged look); an edge pixel half-covered
    by black and white comes out as sRGB(0.5 x light), not as the mean of the codes."""
    from sim_backend.degrade import encode, to_bgr8

    flat = np.full((1, 1, 3), 0.4, np.float32)
    assert to_bgr8(encode(srgb_to_linear(flat), "srgb"))[0, 0, 0] == round(0.4 * 255)
    white, black = srgb_to_linear(np.float32(0.92)), srgb_to_linear(np.float32(0.06))
    mixed = np.full((1, 1, 3), 0.5 * (white + black), np.float32)
    code = int(to_bgr8(encode(mixed, "srgb"))[0, 0, 0])
    assert code == round(255 * float(linear_to_srgb(0.5 * (white + black))))
    assert code > round(255 * 0.49) + 30  # far from the mean of the codes
    assert np.array_equal(encode(mixed, "linear"), mixed)
    gray = cv2.cvtColor(to_bgr8(encode(mixed, "srgb")), cv2.COLOR_BGR2GRAY)
    assert gray.shape == (1, 1)
