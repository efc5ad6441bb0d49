"""The camera's tone curve: 8-bit pixel values back to light (linear intensity) and forth.

Why: cameras and renderers store `encode(light)`, not light. Blur, anti-aliasing and
supersampling mix light linearly, so a blurred black/white step is antisymmetric about the
edge only in linear intensity. Located on encoded values, the gradient peak of a blurred step
moves towards the dark side by a fraction of the blur (about 0.1 px for sRGB and a 1 px blur),
the same way on every border, and tilts the camera (roll). Edges are therefore located on
`luminance(image)`, which undoes the curve first.

Curves: sRGB (IEC 61966-2-1), the default for 8-bit images (what webcams, MJPEG cameras and
renderers such as Unity write); `linear` for raw or linear-light data; `gamma:G` (value =
light ** (1/G)); or a measured table of 256 increasing values (light at each code, any scale)
in a JSON file, for a camera whose curve was measured (a grey chart or an exposure series).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from omnisort_hw.errors import InputError

# Rec. 601 luma weights in OpenCV's BGR order (cv2.COLOR_BGR2GRAY uses the same)
_LUMA_BGR = np.array([0.114, 0.587, 0.299], np.float32)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear light in [0, 1]."""
    x = np.asarray(x, np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB-encoded values in [0, 1] (clipped to the range)."""
    x = np.clip(np.asarray(x, np.float32), 0.0, 1.0)
    lo = x * np.float32(12.92)
    hi = np.float32(1.055) * np.power(np.maximum(x, 0.0031308), np.float32(1 / 2.4)) - 0.055
    return np.where(x <= 0.0031308, lo, hi).astype(np.float32)


@dataclass(frozen=True)
class ToneCurve:
    """A camera's 8-bit tone curve as the light (linear, 0..1) of each code value."""

    name: str
    light: np.ndarray  # (256,) float32, increasing, light[0] = 0 and light[255] = 1

    def __post_init__(self) -> None:
        lut = np.asarray(self.light, np.float64).ravel()
        if lut.size != 256 or not np.all(np.isfinite(lut)):
            raise InputError(f"tone curve {self.name}: needs 256 finite values, got {lut.size}")
        if np.any(np.diff(lut) < 0) or lut[-1] <= lut[0]:
            raise InputError(f"tone curve {self.name}: values must increase with the code")
        object.__setattr__(self, "light", ((lut - lut[0]) / (lut[-1] - lut[0])).astype(np.float32))

    @classmethod
    def srgb(cls) -> ToneCurve:
        return cls("srgb", srgb_to_linear(np.arange(256) / 255.0))

    @classmethod
    def identity(cls) -> ToneCurve:
        """Linear data: code value proportional to light (what this project assumed before)."""
        return cls("linear", np.arange(256, dtype=np.float32) / 255.0)

    @classmethod
    def gamma(cls, g: float) -> ToneCurve:
        if not np.isfinite(g) or g <= 0:
            raise InputError(f"tone curve gamma must be a positive number, got {g}")
        return cls(f"gamma:{g:g}", (np.arange(256) / 255.0) ** g)

    @classmethod
    def parse(cls, spec: str | None) -> ToneCurve:
        """`srgb` (also the default for None or ""), `linear`, `gamma:G`, or a JSON file with
        256 values (a list, or {"light": [...]})."""
        s = (spec or "srgb").strip()
        low = s.lower()
        if low == "srgb":
            return cls.srgb()
        if low in ("linear", "identity"):
            return cls.identity()
        if low.startswith("gamma:"):
            try:
                return cls.gamma(float(s.split(":", 1)[1]))
            except ValueError:
                raise InputError(f"tone curve {s!r}: gamma:G needs a number") from None
        path = Path(s)
        if not path.is_file():
            raise InputError(
                f"tone curve {s!r}: not srgb, linear, gamma:G or a readable JSON table file"
            )
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{path}: not a JSON tone-curve table ({exc})") from None
        values = data.get("light") if isinstance(data, dict) else data
        if not isinstance(values, list):
            raise InputError(f"{path}: expected a list of 256 values or {{'light': [...]}}")
        return cls(path.name, np.asarray(values, np.float64))

    def linearise(self, image: np.ndarray) -> np.ndarray:
        """Light (float32, 0..1) of every value of a uint8 array, same shape."""
        arr = np.asarray(image)
        if arr.dtype != np.uint8:
            raise InputError(f"tone curve: expected 8-bit values, got {arr.dtype}")
        return self.light[arr]

    def luminance(self, bgr: np.ndarray) -> np.ndarray:
        """Linear-light grey (H, W) float32 of a uint8 BGR image, scaled to 0..255 so that
        contrast thresholds keep their grey-level meaning for bright edges."""
        lin = self.linearise(bgr)
        return np.float32(255.0) * (lin @ _LUMA_BGR)


SRGB = ToneCurve.srgb()
