"""Compositing of the laser light and the seeded "real camera" degradation.

The renderer keeps the laser light apart from the scene colour. `compose` adds it as light
that dominates the surface it falls on (`laser.surface_hide`), like a camera exposed for the
laser line. `degrade` first makes the light uneven (a smooth random field along the stripe)
and speckled (gamma-distributed grain), then applies, in the order light takes through a
camera: ambient light, exposure, vignetting, optical blur, a gamma deviation from the
nominal curve, the tone curve (sRGB unless the scene says linear), shot and read noise,
8-bit quantisation and JPEG compression. Every random draw comes from one seeded generator,
so a seed gives the same bytes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

from omnisort_hw.core.radiometry import linear_to_srgb
from sim_backend.camera_effects import (
    EffectParams,
    apply_linear,
    bayer,
    effects_for,
    effects_into,
    laser_seen,
)
from sim_backend.scene import DegradeSpec, LaserSpec


@dataclass(frozen=True)
class DegradeParams:
    """One draw of the degradation settings (stored under `degraded` in the truth)."""

    noise_read: float
    noise_shot: float
    blur_sigma_px: float
    vignetting: float
    exposure_ev: float
    gamma: float
    jpeg_quality: int
    ambient: float
    ambient_tint: tuple[float, float, float]
    laser_uneven: float
    laser_speckle: float
    effects: EffectParams | None = None

    @classmethod
    def draw(
        cls,
        spec: DegradeSpec,
        rng: np.random.Generator,
        laser_rgb: tuple[float, float, float] = (1.0, 0.0, 0.0),
    ) -> DegradeParams:
        """Sample every [lo, hi] range of the spec uniformly; with `effects`, the colour
        camera's effects last, for a laser of colour `laser_rgb` (`camera_effects`)."""

        def u(pair: tuple[float, float]) -> float:
            return float(rng.uniform(pair[0], pair[1])) if pair[1] > pair[0] else float(pair[0])

        tint = rng.uniform(0.85, 1.15, 3)
        return cls(
            noise_read=u(spec.noise_read),
            noise_shot=u(spec.noise_shot),
            blur_sigma_px=u(spec.blur_sigma_px),
            vignetting=u(spec.vignetting),
            exposure_ev=u(spec.exposure_ev),
            gamma=u(spec.gamma),
            jpeg_quality=int(rng.integers(spec.jpeg_quality[0], spec.jpeg_quality[1] + 1)),
            ambient=u(spec.ambient),
            ambient_tint=(float(tint[0]), float(tint[1]), float(tint[2])),
            laser_uneven=u(spec.laser_uneven),
            laser_speckle=u(spec.laser_speckle),
            effects=effects_for(spec, laser_rgb, rng),  # drawn last: the others stay as they were
        )

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-ready dict."""
        d = asdict(self)
        d["ambient_tint"] = list(self.ambient_tint)
        effects_into(d, self.effects)
        return d


def compose(
    base: np.ndarray, laser: np.ndarray, spec: LaserSpec, fx: EffectParams | None = None
) -> np.ndarray:
    """Scene colour (H, W, 3) RGB plus laser light (H, W) -> RGB float image, the laser in
    its colour as the sensor sees it (with the effects `fx`: crosstalk)."""
    lit = laser[..., None]
    hide = np.minimum(lit, 1.0) * np.float32(spec.surface_hide)
    return base * (1.0 - hide) + lit * np.asarray(laser_seen(fx, spec.color.rgb), np.float32)


def encode(rgb: np.ndarray, tone_curve: str) -> np.ndarray:
    """Light in [0, 1] -> the camera's encoded values (sRGB or unchanged for "linear")."""
    return linear_to_srgb(rgb) if tone_curve == "srgb" else rgb


def to_bgr8(rgb: np.ndarray) -> np.ndarray:
    """Float RGB in [0, 1] -> uint8 BGR (OpenCV order, as the Camera interface returns)."""
    out = np.clip(rgb * 255.0 + 0.5, 0.0, 255.0).astype(np.uint8)
    return np.ascontiguousarray(out[..., ::-1])


def smooth_field(rng: np.random.Generator, shape: tuple[int, int], cells: int) -> np.ndarray:
    """A smooth random field in [-1, 1] (bicubic upsampling of a coarse grid)."""
    grid = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
    field = cv2.resize(grid, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)
    return np.clip(field, -1.0, 1.0)


def degrade(
    base: np.ndarray,
    laser: np.ndarray,
    spec: LaserSpec,
    params: DegradeParams,
    rng: np.random.Generator,
    tone_curve: str = "linear",
) -> np.ndarray:
    """The "real camera" image (uint8 BGR) of a rendered frame (`base` and `laser` in linear
    light when `tone_curve` is "srgb")."""
    h, w = laser.shape
    light = laser.copy()
    on = light > 1e-4
    if on.any():
        uneven = 1.0 + params.laser_uneven * smooth_field(rng, (h, w), 24)
        light *= np.maximum(uneven, 0.0)
        if params.laser_speckle > 0:
            k = 1.0 / params.laser_speckle**2
            light[on] *= rng.gamma(k, 1.0 / k, int(on.sum())).astype(np.float32)
    fx = params.effects
    img = compose(base, light, spec, fx)
    ambient = params.ambient * (1.0 + 0.5 * smooth_field(rng, (h, w), 4))
    img += ambient[..., None] * np.asarray(params.ambient_tint, np.float32)
    img *= np.float32(2.0**params.exposure_ev)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - (w - 1) / 2.0) ** 2 + (yy - (h - 1) / 2.0) ** 2) / ((min(w, h) / 2.0) ** 2)
    img *= (1.0 - params.vignetting * np.clip(r2, 0.0, 1.0))[..., None]
    if params.blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), params.blur_sigma_px)
    if fx is not None:
        img = apply_linear(img, fx)
    img = encode(np.clip(img, 0.0, 1.0) ** np.float32(params.gamma), tone_curve)
    sigma = np.sqrt(params.noise_shot**2 * img + params.noise_read**2)
    img = img + sigma * rng.standard_normal(img.shape, dtype=np.float32)
    bgr = to_bgr8(img)
    if fx is not None and fx.bayer:
        bgr = bayer(bgr)
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, params.jpeg_quality])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    if decoded is None:
        raise RuntimeError("JPEG decoding failed")
    return decoded
