"""The simulated camera's sensor: exposure, gain, shot and read noise, saturation, lamp flicker
and pixel formats, with an independent noise draw for every frame.

Light (linear, relative to the full well at the nominal 10 ms and gain 1): the renderer's
scene colour is the surface under the room lamps, the laser's light and any sunlight are added
to it (light adds; nothing hides the surface). What stays fixed for one camera and scene is
drawn once from the camera's seed (`SensorParams`): full well, read noise, vignetting, optical
blur, the gamma deviation, the ambient tint, and the laser's unevenness and speckle (a static
scene keeps its speckle pattern). What changes every frame is drawn from the frame's own seed:
photon shot noise, read noise, and the phase of the lamps' 100 Hz flicker.

A frame of exposure t and gain g collects e = FW (t / t0) (f base + sun + laser) electrons
(f: the lamps' light averaged over the exposure, 1 + m sinc(100 Hz t) cos(phase), so an
exposure of whole 10 ms periods does not flicker), plus Normal(0, e) shot and Normal(0, r^2)
read noise; the well clips at FW, the ADC at 1 after the gain. Then the gamma deviation, the
tone curve, 8 bits and the pixel format: MJPG is JPEG with 4:2:0 chroma, YUYV keeps luma and
halves the chroma horizontally (4:2:2), BGR3 keeps every sample.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from functools import lru_cache

import cv2
import numpy as np

from sim_backend.camera_effects import (
    EffectParams,
    apply_linear,
    bayer,
    effects_for,
    effects_into,
    laser_seen,
)
from sim_backend.degrade import encode, smooth_field, to_bgr8
from sim_backend.scene import DegradeSpec, LaserSpec

NOMINAL_EXPOSURE_MS = 10.0
MAINS_FLICKER_HZ = 100.0
PIXEL_FORMATS = ("MJPG", "YUYV", "BGR3")


@dataclass(frozen=True)
class SensorParams:
    """What one simulated camera keeps from frame to frame (drawn once from its seed)."""

    full_well_e: float
    read_noise_e: float
    blur_sigma_px: float
    vignetting: float
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
    ) -> SensorParams:
        """The scene's [degrade] ranges, sampled uniformly. `noise_shot` is the shot noise at
        full scale (so FW = 1 / noise_shot^2 electrons), `noise_read` the read noise as a
        fraction of full scale at gain 1. With `effects`, the colour camera's effects are
        drawn last (the other draws stay as they were) for a laser of colour `laser_rgb`."""

        def u(pair: tuple[float, float]) -> float:
            return float(rng.uniform(pair[0], pair[1])) if pair[1] > pair[0] else float(pair[0])

        shot = u(spec.noise_shot)
        fw = 1.0 / max(shot, 1e-4) ** 2
        tint = rng.uniform(0.85, 1.15, 3)
        return cls(
            full_well_e=fw,
            read_noise_e=u(spec.noise_read) * fw,
            blur_sigma_px=u(spec.blur_sigma_px),
            vignetting=u(spec.vignetting),
            gamma=u(spec.gamma),
            jpeg_quality=int(rng.integers(spec.jpeg_quality[0], spec.jpeg_quality[1] + 1)),
            ambient=u(spec.ambient),
            ambient_tint=(float(tint[0]), float(tint[1]), float(tint[2])),
            laser_uneven=u(spec.laser_uneven),
            laser_speckle=u(spec.laser_speckle),
            effects=effects_for(spec, laser_rgb, rng),  # drawn last: the others stay as they were
        )

    def to_dict(self) -> dict[str, object]:
        d = asdict(self)
        d["ambient_tint"] = list(self.ambient_tint)
        effects_into(d, self.effects)
        return d


def flicker_factor(depth: float, exposure_ms: float, phase: float) -> float:
    """The lamps' light averaged over one exposure, relative to their mean (see module doc)."""
    x = MAINS_FLICKER_HZ * exposure_ms / 1000.0
    return float(1.0 + depth * np.sinc(x) * np.cos(phase))


@dataclass
class OpticalImage:
    """Light reaching the sensor at the nominal exposure, through the lens (vignetting, blur):
    lamp-lit scene (flickers), steady light (ambient, sun) and laser light (switched)."""

    lamp: np.ndarray
    steady: np.ndarray
    laser: np.ndarray

    @classmethod
    def prepare(
        cls,
        base: np.ndarray,
        laser: np.ndarray,
        spec: LaserSpec,
        params: SensorParams,
        rng: np.random.Generator,
        steady: np.ndarray | None = None,
        laser_extra: np.ndarray | None = None,
    ) -> OpticalImage:
        """The static optics of one rendered state: `base` (H, W, 3) lamp-lit colour, `laser`
        (H, W) laser intensity, optional `steady` (H, W, 3) non-flickering light and
        `laser_extra` (H, W, 3) more laser light (a reflection)."""
        h, w = laser.shape
        light = laser.astype(np.float32).copy()
        on = light > 1e-4
        if on.any():
            uneven = 1.0 + params.laser_uneven * smooth_field(rng, (h, w), 24)
            light *= np.maximum(uneven, 0.0)
            if params.laser_speckle > 0:
                k = 1.0 / params.laser_speckle**2
                light[on] *= rng.gamma(k, 1.0 / k, int(on.sum())).astype(np.float32)
        fx = params.effects
        las = light[..., None] * np.asarray(laser_seen(fx, spec.color.rgb), np.float32)
        if laser_extra is not None:
            las = las + laser_extra.astype(np.float32)
        amb = params.ambient * (1.0 + 0.5 * smooth_field(rng, (h, w), 4))
        st = amb[..., None] * np.asarray(params.ambient_tint, np.float32)
        if steady is not None:
            st = st + steady.astype(np.float32)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((xx - (w - 1) / 2.0) ** 2 + (yy - (h - 1) / 2.0) ** 2) / ((min(w, h) / 2.0) ** 2)
        vig = (1.0 - params.vignetting * np.clip(r2, 0.0, 1.0))[..., None]

        def optics(img: np.ndarray) -> np.ndarray:
            out = (img * vig).astype(np.float32)
            if params.blur_sigma_px > 0:
                out = cv2.GaussianBlur(out, (0, 0), params.blur_sigma_px)
            return apply_linear(out, fx) if fx is not None else out

        return cls(optics(base.astype(np.float32)), optics(st), optics(las))


@dataclass(frozen=True)
class Exposure:
    """One frame's settings: exposure (ms), gain, laser on, lamps' flicker depth, format."""

    exposure_ms: float = NOMINAL_EXPOSURE_MS
    gain: float = 1.0
    laser_on: bool = True
    flicker_depth: float = 0.0
    pixel_format: str = "MJPG"


def expose(
    optical: OpticalImage,
    params: SensorParams,
    settings: Exposure,
    rng: np.random.Generator,
    tone_curve: str = "linear",
) -> tuple[np.ndarray, dict[str, float]]:
    """One frame (uint8 BGR) and what it was exposed with (flicker factor, clipped fraction)."""
    if settings.pixel_format not in PIXEL_FORMATS:
        raise ValueError(f"pixel format {settings.pixel_format!r} not in {PIXEL_FORMATS}")
    f = flicker_factor(settings.flicker_depth, settings.exposure_ms, rng.uniform(0, 2 * np.pi))
    k = np.float32(params.full_well_e * settings.exposure_ms / NOMINAL_EXPOSURE_MS)
    # In place, one full-size buffer at a time (a 1920 px frame is 11 M samples): the same
    # operations in the same order as written out, so the same bytes.
    e = np.multiply(optical.lamp, np.float32(f))
    e += optical.steady
    if settings.laser_on:
        e += optical.laser
    np.maximum(e, 0.0, out=e)
    e *= k
    sigma = e + np.float32(params.read_noise_e**2)
    np.sqrt(sigma, out=sigma)
    sigma *= rng.standard_normal(e.shape, dtype=np.float32)
    e += sigma
    del sigma
    fw = np.float32(params.full_well_e)
    np.clip(e, 0.0, fw, out=e)
    e *= np.float32(settings.gain / params.full_well_e)
    np.clip(e, 0.0, 1.0, out=e)
    clipped = float(np.count_nonzero(e >= 1.0) / e.size)
    e *= np.float32(_LUT_MAX)
    e += np.float32(0.5)
    idx = e[..., ::-1].astype(np.uint16)  # RGB -> BGR while converting
    del e
    bgr = _code_lut(params.gamma, tone_curve)[idx]
    if params.effects is not None and params.effects.bayer:
        bgr = bayer(bgr)
    if settings.pixel_format == "MJPG":
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, params.jpeg_quality])
        if not ok:
            raise RuntimeError("JPEG encoding failed")
        bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    elif settings.pixel_format == "YUYV":
        bgr = _chroma_422(bgr)
    return bgr, {"flicker": f, "clipped_fraction": clipped}


_LUT_MAX = 65535


@lru_cache(maxsize=16)
def _code_lut(gamma: float, tone_curve: str) -> np.ndarray:
    """8-bit code of every 16-bit ADC value: the gamma deviation, then the tone curve."""
    x = np.arange(_LUT_MAX + 1, dtype=np.float32) / np.float32(_LUT_MAX)
    return to_bgr8(encode(x ** np.float32(gamma), tone_curve)[:, None, None].repeat(3, 2))[
        :, 0, 0
    ].copy()


def _chroma_422(bgr: np.ndarray) -> np.ndarray:
    """YUYV: full-resolution luma, each chroma sample shared by two horizontal pixels."""
    ycc = cv2.cvtColor(bgr, cv2.COLOR_BGR2YCrCb)
    w = ycc.shape[1] - ycc.shape[1] % 2
    pair = ycc[:, :w, 1:].reshape(ycc.shape[0], w // 2, 2, 2).astype(np.uint16)
    mean = ((pair[:, :, 0] + pair[:, :, 1] + 1) // 2).astype(np.uint8)
    ycc[:, :w, 1:] = np.repeat(mean, 2, axis=1)
    return cv2.cvtColor(ycc, cv2.COLOR_YCrCb2BGR)
