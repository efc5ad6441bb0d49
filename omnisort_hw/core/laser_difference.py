"""The laser's own light from laser-on and laser-off frames: averaging, differencing in linear
light, lamp-flicker compensation and saturation of the stripe core. Arrays in, arrays out.

Why in linear light: light adds, so on - off is exactly the laser's light there (whatever the
surface colour: red cubes and red tape vanish, sunlight too where it does not clip). Lamps
flickering at 100 Hz scale the lamp-lit scene between frames; the global gain between the on
and off means is estimated as the median of their ratio over well exposed pixels (the stripe
covers well under 1 % of the image, so the median ignores it) and divided out.

Pixels clipped in any frame carry no laser difference (the laser cannot raise a clipped value)
and are set to zero; clipped pixels that the laser made clip (clipped with the laser on, not
with it off) are counted as the stripe's clipped core, which the capture answers by exposing
shorter.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.core.laser_colour import as_red_laser
from omnisort_hw.core.laser_stripe import check_bgr
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import InputError

_PEAK_LEVEL = 200.0  # the stripe's robust peak in the 8-bit difference image
_NOISE_K = 6.0  # "laser light here": difference above this many noise standard deviations


@dataclass(frozen=True)
class FrameStack:
    """The mean of N frames of one kind, in linear light, and where any frame clipped."""

    mean: np.ndarray  # (H, W, 3) float32 linear light 0..1
    clipped: np.ndarray  # (H, W) bool: some channel was 255 in some frame
    frames: int


def stack_frames(frames: Sequence[np.ndarray], tone: ToneCurve, what: str) -> FrameStack:
    """Average uint8 BGR frames in linear light (`what` names them in errors)."""
    if not frames:
        raise InputError(f"{what}: no frames")
    first = check_bgr(frames[0], what)
    acc = np.zeros(first.shape, np.float32)
    peak = np.zeros(first.shape, np.uint8)  # each sample's largest value over the frames
    lut = np.ascontiguousarray(tone.light, np.float32)
    for i, f in enumerate(frames):
        img = check_bgr(f, f"{what} frame {i}")
        if img.shape != first.shape:
            raise InputError(f"{what} frame {i} is {img.shape}, frame 0 is {first.shape}")
        acc += cv2.LUT(img, lut)  # tone.linearise, multi-threaded
        np.maximum(peak, img, out=peak)
    clipped = (peak == 255).any(axis=2)
    acc /= np.float32(len(frames))
    return FrameStack(acc, clipped, len(frames))


@dataclass(frozen=True)
class LaserDifference:
    """The laser's light as an 8-bit BGR image for the stripe extractor, and what it saw."""

    image: np.ndarray  # (H, W, 3) uint8, laser light scaled so the stripe peaks near 200
    scale: float  # 8-bit levels per unit of linear light
    flicker_gain: float  # on / off gain of the lamp-lit scene that was divided out
    noise: float  # robust noise of the red difference (linear light)
    stripe_pixels: int  # pixels with laser light above _NOISE_K noise
    clipped_core_pixels: int  # of those, clipped with the laser on and not with it off
    blind_pixels: int  # pixels clipped with the laser off (no stripe can be seen there)

    @property
    def clipped_fraction(self) -> float:
        """Share of the stripe's pixels that the laser drove into clipping."""
        return self.clipped_core_pixels / max(1, self.stripe_pixels)


def _robust_noise(x: np.ndarray) -> float:
    """Standard deviation from neighbouring-pixel differences (MAD), every 4th row."""
    d = np.diff(x[::4], axis=1).ravel()
    mad = float(np.median(np.abs(d - np.median(d))))
    return 1.4826 * mad / np.sqrt(2.0)


def laser_difference(on: FrameStack, off: FrameStack, color: str = "red") -> LaserDifference:
    """on - g off in linear light (g: the flicker gain, see the module docstring); `color`:
    the laser's, whose channel's excess over the others is its light."""
    if on.mean.shape != off.mean.shape:
        raise InputError(f"laser-on frames are {on.mean.shape}, laser-off {off.mean.shape}")
    lum_on = on.mean.mean(axis=2)
    lum_off = off.mean.mean(axis=2)
    ok = ~(on.clipped | off.clipped) & (lum_off > 0.02) & (lum_off < 0.9)
    ratio = lum_on[ok][::7] / lum_off[ok][::7]
    gain = float(np.median(ratio)) if ratio.size > 100 else 1.0
    diff = on.mean - np.float32(gain) * off.mean
    blind = off.clipped
    seen = as_red_laser(diff, color)
    red = seen[..., 2] - np.maximum(seen[..., 1], seen[..., 0])
    noise = _robust_noise(red)
    laser = red > _NOISE_K * max(noise, 1e-6)
    clipped_core = laser & on.clipped & ~blind
    diff[on.clipped | blind] = 0.0
    lit = laser & ~(on.clipped | blind)
    peaks = red[lit]
    peak = float(np.percentile(peaks, 95)) if peaks.size >= 20 else float(red.max(initial=0.0))
    scale = _PEAK_LEVEL / max(peak, 1e-6)
    image = np.clip(diff * np.float32(scale) + 0.5, 0.0, 255.0).astype(np.uint8)
    return LaserDifference(
        image=image,
        scale=scale,
        flicker_gain=gain,
        noise=noise,
        stripe_pixels=int(laser.sum()),
        clipped_core_pixels=int(clipped_core.sum()),
        blind_pixels=int(blind.sum()),
    )


def response_gamma(short: FrameStack, long: FrameStack, ratio: float, tone: ToneCurve) -> float:
    """The camera's deviation from its nominal tone curve, from two exposures of one scene.

    Means linearised with the nominal curve are L' = (k L)^g; exposures in the ratio `ratio`
    give L'_long / L'_short = ratio^g on every pixel that clips in neither (the median over
    them ignores the few that moved or flickered). g = 1 when the curve is right."""
    lum_s = short.mean.mean(axis=2)
    lum_l = long.mean.mean(axis=2)
    ok = ~(short.clipped | long.clipped) & (lum_s > 0.03) & (lum_l < 0.9)
    if ok.sum() < 1000 or ratio <= 1.0:
        return 1.0
    r = lum_l[ok] / lum_s[ok]
    return float(np.log(np.median(r)) / np.log(ratio))


def corrected_tone(tone: ToneCurve, gamma: float) -> ToneCurve:
    """The nominal curve with the measured deviation undone (light = nominal^(1/g))."""
    if abs(gamma - 1.0) < 1e-6:
        return tone
    return ToneCurve(f"{tone.name}^(1/{gamma:.4f})", tone.light.astype(np.float64) ** (1 / gamma))


def encode_mean(stack: FrameStack, tone: ToneCurve) -> np.ndarray:
    """The mean frame back in the camera's 8-bit code values (for target and colour features,
    which expect what the camera writes)."""
    light = tone.light.astype(np.float64)
    # the nearest code, ties to the lower one: values above the midpoint between two codes
    midpoints = (light[:-1] + light[1:]) / 2.0
    codes = np.searchsorted(midpoints, stack.mean.ravel(), side="left")
    return codes.astype(np.uint8).reshape(stack.mean.shape)
