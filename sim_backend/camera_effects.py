"""What a real colour camera does to a laser line that the renders lacked, measured on real
photographs (docs/real_light.md says how):

- **crosstalk**: the colour filters pass some of the laser's narrow line to the other two
  channels, so a bright line clips to white at its core and keeps coloured flanks
  (`laser_leak`; the shares per laser colour come from the development photographs);
- **lateral chromatic aberration**: the lens images red and blue at slightly different
  magnifications from green, so colours part toward the rim (`lateral_chromatic`);
- **bloom**: a part of the light scatters in the lens and sensor into a wide halo round
  bright light (`bloom`);
- **Bayer demosaicing**: each pixel samples one colour through an RGGB mosaic and the camera
  interpolates the other two, which leaves colour fringes one or two pixels wide on every
  sharp luminance edge, black print on white paper above all (`bayer`).

Arrays in, arrays out: the first three act on linear light (H, W, 3) RGB float before the
sensor's well clips it, the mosaic on the 8-bit BGR frame before compression.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

from sim_backend.scene import DegradeSpec

# Share of the laser's main channel that each other channel sees, [lo, hi], measured on the
# development photographs as the slope of each channel against the laser's channel across
# unclipped stripes (median per set; the spread between sets and photographs gives the range).
# Red, 3 sets of a 650 nm line: blue 0.29 to 0.41, green -0.2 to 0.1 (medians per set). Green,
# one set: red 0.68, blue 0.86 (8-bit codes, as measured). Blue: no photographs, so the red
# line's shares with the channels' roles mirrored (an assumption, said as one in the docs).
LASER_LEAK: dict[int, dict[int, tuple[float, float]]] = {  # RGB indices
    0: {1: (0.0, 0.15), 2: (0.2, 0.55)},  # red light: green, blue
    1: {0: (0.6, 0.75), 2: (0.6, 0.9)},  # green light: red, blue
    2: {0: (0.2, 0.55), 1: (0.0, 0.15)},  # blue light: red, green (mirrored from red)
}


@dataclass(frozen=True)
class EffectParams:
    """One camera's draw of the effects (kept in the truth under `degraded`)."""

    laser_leak: tuple[float, float, float]  # the laser's colour as the sensor sees it, RGB
    chromatic_px: tuple[float, float]  # red's and blue's radial shift at the corner, px
    bloom: float  # share of the light in the halo
    bloom_sigma_px: float
    bayer: bool

    def to_dict(self) -> dict[str, object]:
        d = asdict(self)
        d["laser_leak"], d["chromatic_px"] = list(self.laser_leak), list(self.chromatic_px)
        return d


def laser_seen(
    fx: EffectParams | None, rgb: tuple[float, float, float]
) -> tuple[float, float, float]:
    """The laser's colour as the sensor sees it: with the effects `fx`, its crosstalk; else
    the scene's colour `rgb`."""
    return fx.laser_leak if fx is not None else rgb


def effects_into(d: dict[str, object], fx: EffectParams | None) -> None:
    """A camera's parameters as a dict (`d`, from `asdict`) with its effects as JSON, or
    without the key when it has none (the truth of such a camera is as it was)."""
    if fx is None:
        d.pop("effects", None)
    else:
        d["effects"] = fx.to_dict()


def effects_for(
    spec: DegradeSpec, laser_rgb: tuple[float, float, float], rng: np.random.Generator
) -> EffectParams | None:
    """A scene's [degrade] effects drawn for a laser of colour `laser_rgb`, or None when the
    scene does not ask for them."""
    if not spec.effects:
        return None
    return draw_effects(
        laser_rgb,
        (spec.chromatic_red_px, spec.chromatic_blue_px),
        spec.bloom,
        spec.bloom_sigma_px,
        spec.bayer,
        rng,
    )


def draw_effects(
    laser_rgb: tuple[float, float, float],
    chromatic_px: tuple[tuple[float, float], tuple[float, float]],
    bloom_share: tuple[float, float],
    bloom_sigma_px: tuple[float, float],
    bayer: bool,
    rng: np.random.Generator,
) -> EffectParams:
    """Sample the effects: the leak from LASER_LEAK for the laser's main channel, the other
    ranges as given ([lo, hi], uniform; `chromatic_px`: red's and blue's range)."""
    main = int(np.argmax(laser_rgb))
    seen = np.asarray(laser_rgb, float).copy()
    for ch, (lo, hi) in sorted(LASER_LEAK[main].items()):
        seen[ch] = max(seen[ch], float(rng.uniform(lo, hi)) * seen[main])
    return EffectParams(
        laser_leak=(float(seen[0]), float(seen[1]), float(seen[2])),
        chromatic_px=(float(rng.uniform(*chromatic_px[0])), float(rng.uniform(*chromatic_px[1]))),
        bloom=float(rng.uniform(*bloom_share)),
        bloom_sigma_px=float(rng.uniform(*bloom_sigma_px)),
        bayer=bayer,
    )


def lateral_chromatic(rgb: np.ndarray, shift_px: tuple[float, float]) -> np.ndarray:
    """(H, W, 3) RGB with red and blue magnified about the image centre so that a point at the
    corner moves outward by `shift_px` (red, blue; negative: inward) and green stays."""
    h, w = rgb.shape[:2]
    cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
    corner = float(np.hypot(cx, cy))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    out = rgb.copy()
    for ch, shift in ((0, shift_px[0]), (2, shift_px[1])):
        if shift == 0.0:
            continue
        m = 1.0 + shift / corner  # magnification: the corner moves by `shift`
        map_x = (cx + (xx - cx) / m).astype(np.float32)
        map_y = (cy + (yy - cy) / m).astype(np.float32)
        out[..., ch] = cv2.remap(
            np.ascontiguousarray(rgb[..., ch]),
            map_x,
            map_y,
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
    return out


def bloom(rgb: np.ndarray, share: float, sigma_px: float) -> np.ndarray:
    """(H, W, 3) light with `share` of it spread into a Gaussian halo of `sigma_px` (the light
    is kept: what the halo gains the source loses)."""
    if share <= 0.0 or sigma_px <= 0.0:
        return rgb
    halo = cv2.GaussianBlur(rgb, (0, 0), sigma_px, borderType=cv2.BORDER_REFLECT)
    return (1.0 - share) * rgb + share * halo


# An RGGB mosaic: the sample each pixel keeps, by (row % 2, column % 2), as a BGR index.
_RGGB = np.array([[2, 1], [1, 0]])


def bayer(bgr: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 BGR as a colour camera delivers it: one channel kept per pixel through
    an RGGB mosaic, the other two interpolated (OpenCV's bilinear demosaicing, as a simple
    camera's processor does)."""
    h, w = bgr.shape[:2]
    rows, cols = np.indices((h, w))
    mosaic = np.take_along_axis(bgr, _RGGB[rows % 2, cols % 2][..., None], axis=2)[..., 0]
    # OpenCV names a Bayer pattern by the 2x2 block starting at the second row and column:
    # an RGGB sensor is its BayerBG.
    return cv2.cvtColor(np.ascontiguousarray(mosaic), cv2.COLOR_BayerBG2BGR)


def apply_linear(rgb: np.ndarray, fx: EffectParams) -> np.ndarray:
    """The lens's effects on linear light (H, W, 3) RGB: chromatic aberration, then bloom."""
    out = lateral_chromatic(rgb, fx.chromatic_px) if any(fx.chromatic_px) else rgb
    return bloom(out, fx.bloom, fx.bloom_sigma_px)
