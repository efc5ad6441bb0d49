"""Scaramuzza / OCamCalib omnidirectional camera model, vectorised.

Conventions (see docs/frames.md):
- pixels are (u, v) = (column, row), origin at the centre of the top-left pixel;
- rays are in the camera frame C (OpenCV): x along +u, y along +v, z out of the lens;
- the forward polynomial f(rho) = a0 + a2 rho^2 + ... keeps OCamCalib's sign (a0 < 0);
- the stretch terms (c, d, e) keep OCamCalib's meaning: they act on (row, column) offsets,
  so the numbers read from or written to calib_results.txt are the same numbers;
- the inverse polynomial gives rho as a function of theta, the angle between the ray and
  +z of C, fitted automatically to a maximum error (default 0.01 px) over the image.

Pixel -> ray: (du, dv) = (u - cu, v - cv); solve [[c, d], [e, 1]] (x_o, y_o) = (dv, du);
rho = |(x_o, y_o)|; the ray is (y_o, x_o, -f(rho)) in C (OCamCalib's frame has x along rows
and z into the scene negative; swapping x/y and negating z is a proper rotation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from omnisort_hw.errors import InputError

INVERSE_TOLERANCE_PX = 0.01
_MAX_INVERSE_DEGREE = 24
_BLOCK = 32768


def _horner(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate sum coeffs[i] x^i (ascending powers) by Horner's rule."""
    out = np.full(np.shape(x), coeffs[-1], dtype=float)
    for c in coeffs[-2::-1]:
        out *= x
        if c != 0.0:
            out += c
    return out


def _blockwise(func: Any, arr: np.ndarray, n_in: int, n_out: int) -> np.ndarray:
    """Apply a row-wise map in blocks that fit the CPU cache (2x faster for 1e6 points)."""
    a = np.asarray(arr, dtype=float)
    if a.shape[-1] != n_in:
        raise ValueError(f"expected an array of shape (..., {n_in}), got {a.shape}")
    flat = a.reshape(-1, n_in)
    out = np.empty((flat.shape[0], n_out))
    for start in range(0, flat.shape[0], _BLOCK):
        out[start : start + _BLOCK] = func(flat[start : start + _BLOCK])
    return out.reshape(*a.shape[:-1], n_out)


def _theta_of_rho(poly: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Angle from the optical axis of the ray through sensor radius rho."""
    return np.arctan2(rho, -_horner(poly, rho))


def fit_polynomial_to_tolerance(
    x: np.ndarray,
    y: np.ndarray,
    tol: float,
    x_check: np.ndarray | None = None,
    y_check: np.ndarray | None = None,
    max_degree: int = _MAX_INVERSE_DEGREE,
) -> tuple[np.ndarray, float]:
    """Least-squares polynomial y(x) of the lowest degree whose max error on the check set <= tol.

    Returns ascending coefficients and the achieved max error. Columns are scaled for
    conditioning; if no degree reaches `tol`, the best one is returned with its error.
    """
    x_check = x if x_check is None else x_check
    y_check = y if y_check is None else y_check
    scale = float(np.max(np.abs(x))) or 1.0
    xs = x / scale
    best: tuple[np.ndarray, float] | None = None
    for degree in range(1, max_degree + 1):
        vander = np.vander(xs, degree + 1, increasing=True)
        coef_scaled, *_ = np.linalg.lstsq(vander, y, rcond=None)
        coef = coef_scaled / scale ** np.arange(degree + 1)
        err = float(np.max(np.abs(_horner(coef, x_check) - y_check)))
        if best is None or err < best[1]:
            best = (coef, err)
        if err <= tol:
            return coef, err
    assert best is not None
    return best


@dataclass(frozen=True, eq=False)
class OcamModel:
    """An OCamCalib camera: forward polynomial, centre, stretch, and a fitted inverse."""

    poly: np.ndarray
    center_uv: tuple[float, float]
    stretch: tuple[float, float, float]
    image_size: tuple[int, int]
    inv_poly: np.ndarray = field(repr=False)
    theta_max: float
    inv_error_px: float
    # The intrinsic calibration's covariance, when known (core.intrinsics_uncertainty:
    # `parameters`, `covariance`, `rho_scale`, `poly_degree`): carried with the model into
    # system.json so that every map point's sigma can include it.
    uncertainty: dict[str, Any] | None = field(default=None, repr=False)

    @classmethod
    def create(
        cls,
        poly: np.ndarray | list[float],
        center_uv: tuple[float, float],
        stretch: tuple[float, float, float] = (1.0, 0.0, 0.0),
        image_size: tuple[float, float] = (1920, 1920),
        tol_px: float = INVERSE_TOLERANCE_PX,
    ) -> OcamModel:
        """Build a model and fit its inverse polynomial over the whole image."""
        poly_arr = np.asarray(poly, dtype=float).copy()
        if poly_arr.ndim != 1 or poly_arr.size < 2:
            raise InputError("camera model: 'poly' needs at least a0 and a1")
        for name, values in (("poly", poly_arr), ("center_uv", center_uv), ("stretch", stretch)):
            if not np.all(np.isfinite(np.asarray(values, dtype=float))):
                raise InputError(f"camera model: {name!r} holds a NaN or infinite value")
        if any(not math.isfinite(n) or int(n) != n or n < 1 for n in image_size):
            raise InputError(
                f"camera model: 'image_size' must be two positive whole pixel counts, "
                f"got {list(image_size)}"
            )
        if not all(0 <= float(c) < int(n) for c, n in zip(center_uv, image_size, strict=True)):
            raise InputError(
                f"camera model: 'center_uv' {list(center_uv)} lies outside the "
                f"{int(image_size[0])}x{int(image_size[1])} image"
            )
        if poly_arr[0] >= 0:
            raise InputError(
                f"camera model: a0 must be negative (OCamCalib sign), got {poly_arr[0]}"
            )
        c, d, e = (float(s) for s in stretch)
        if abs(c - d * e) < 1e-9:
            raise InputError("camera model: stretch matrix [[c, d], [e, 1]] is singular")
        width, height = int(image_size[0]), int(image_size[1])
        probe = cls(
            poly=poly_arr,
            center_uv=(float(center_uv[0]), float(center_uv[1])),
            stretch=(c, d, e),
            image_size=(width, height),
            inv_poly=np.zeros(1),
            theta_max=np.pi,
            inv_error_px=np.inf,
        )
        rho_limit = probe._rho_limit()
        rho_dense = np.linspace(0.0, rho_limit, 20001)
        theta_dense = _theta_of_rho(poly_arr, rho_dense)
        decreasing = np.nonzero(np.diff(theta_dense) <= 0)[0]
        if decreasing.size:
            cut = int(decreasing[0])
            if cut < 100:
                raise InputError("camera model: polynomial is not monotonic near the centre")
            rho_dense, theta_dense = rho_dense[: cut + 1], theta_dense[: cut + 1]
        theta_max = float(theta_dense[-1])
        # Fit rho(theta) on Chebyshev-spaced samples; check on a denser uniform set.
        theta_fit = theta_max * 0.5 * (1 - np.cos(np.linspace(0, np.pi, 600)))
        theta_chk = np.linspace(0.0, theta_max, 5001)
        rho_fit = probe._invert_theta(theta_fit, rho_dense, theta_dense)
        rho_chk = probe._invert_theta(theta_chk, rho_dense, theta_dense)
        # Pixel error of a radius error is at most the largest singular value of the stretch.
        gain = float(np.linalg.svd(np.array([[c, d], [e, 1.0]]), compute_uv=False)[0])
        inv, err = fit_polynomial_to_tolerance(
            theta_fit, rho_fit, 0.5 * tol_px / gain, theta_chk, rho_chk
        )
        return cls(
            poly=poly_arr,
            center_uv=probe.center_uv,
            stretch=probe.stretch,
            image_size=probe.image_size,
            inv_poly=inv,
            theta_max=theta_max,
            inv_error_px=err * gain,
        )

    @classmethod
    def equidistant(
        cls,
        width: int = 1920,
        height: int = 1920,
        fov_deg: float = 185.0,
        center_uv: tuple[float, float] | None = None,
    ) -> OcamModel:
        """An ideal equidistant fisheye (rho = k theta) whose image circle of `fov_deg` fits the
        shorter side. The forward polynomial is fitted to rho cot(rho / k) to within 1e-6 rad."""
        radius = min(width, height) / 2.0
        k = radius / np.deg2rad(fov_deg / 2.0)
        rho_max = float(np.hypot(width, height) / 2.0 + 2.0)
        if rho_max / k >= np.pi * 0.98:
            rho_max = np.pi * 0.98 * k
        rho = np.linspace(0.0, rho_max, 4000)
        target_f = np.empty_like(rho)
        target_f[0] = -k
        target_f[1:] = -rho[1:] / np.tan(rho[1:] / k)
        poly = None
        for degree in range(4, 21):
            # a1 = 0: fit a0 + a2 r^2 + ... + aN r^N with scaled columns.
            powers = np.array([0, *range(2, degree + 1)])
            vander = (rho[:, None] / rho_max) ** powers[None, :]
            coef, *_ = np.linalg.lstsq(vander, target_f, rcond=None)
            full = np.zeros(degree + 1)
            full[powers] = coef / rho_max**powers
            if np.max(np.abs(_theta_of_rho(full, rho) - rho / k)) < 1e-6:
                poly = full
                break
        if poly is None:
            raise InputError(f"equidistant model: cannot fit fov {fov_deg} deg")
        centre = center_uv if center_uv is not None else ((width - 1) / 2.0, (height - 1) / 2.0)
        return cls.create(poly, centre, (1.0, 0.0, 0.0), (width, height))

    # ---- internal helpers -------------------------------------------------------------

    def _sensor_from_offsets(self, du: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Undo the stretch: pixel offsets (du, dv) -> OCamCalib sensor coordinates (x_o, y_o)."""
        c, d, e = self.stretch
        if (c, d, e) == (1.0, 0.0, 0.0):
            return dv, du
        inv_det = 1.0 / (c - d * e)
        x_o = inv_det * (dv - d * du)
        y_o = inv_det * (c * du - e * dv)
        return x_o, y_o

    def _rho_limit(self) -> float:
        """Largest sensor radius among the image corners (a pixel's worth of margin)."""
        w, h = self.image_size
        corners = np.array([[-1.0, -1.0], [w, -1.0], [-1.0, h], [w, h]])
        x_o, y_o = self._sensor_from_offsets(
            corners[:, 0] - self.center_uv[0], corners[:, 1] - self.center_uv[1]
        )
        return float(np.max(np.sqrt(x_o * x_o + y_o * y_o)))

    def _invert_theta(
        self, theta: np.ndarray, rho_dense: np.ndarray, theta_dense: np.ndarray
    ) -> np.ndarray:
        """rho with theta(rho) = theta: interpolation, then Newton steps on the exact model."""
        rho = np.interp(theta, theta_dense, rho_dense)
        dpoly = np.polynomial.polynomial.polyder(self.poly)
        for _ in range(6):
            f = _horner(self.poly, rho)
            df = _horner(dpoly, rho)
            # d/drho atan2(rho, -f) = (-f + rho f') / (rho^2 + f^2)
            dtheta = (-f + rho * df) / (rho**2 + f**2)
            rho = rho - (np.arctan2(rho, -f) - theta) / dtheta
        return np.clip(rho, 0.0, None)

    # ---- public mapping ---------------------------------------------------------------

    @property
    def fov_deg(self) -> float:
        """Full field of view covered by the image (twice the largest angle from the axis)."""
        return float(np.rad2deg(2 * self.theta_max))

    def pixel_to_ray(self, uv: np.ndarray) -> np.ndarray:
        """(..., 2) pixels -> (..., 3) unit rays in C. Works beyond 180 degrees (z < 0)."""
        return _blockwise(self._pixel_to_ray_block, uv, 2, 3)

    def ray_to_pixel(self, xyz: np.ndarray) -> np.ndarray:
        """(..., 3) points or rays in C -> (..., 2) pixels through the fitted inverse polynomial."""
        return _blockwise(self._ray_to_pixel_block, xyz, 3, 2)

    def _pixel_to_ray_block(self, uv: np.ndarray) -> np.ndarray:
        x_o, y_o = self._sensor_from_offsets(
            uv[..., 0] - self.center_uv[0], uv[..., 1] - self.center_uv[1]
        )
        rho2 = x_o * x_o
        rho2 += y_o * y_o
        z = _horner(-self.poly, np.sqrt(rho2))
        rho2 += z * z
        inv_norm = np.sqrt(rho2, out=rho2)
        np.divide(1.0, inv_norm, out=inv_norm)
        out = np.empty((*x_o.shape, 3))
        np.multiply(y_o, inv_norm, out=out[..., 0])
        np.multiply(x_o, inv_norm, out=out[..., 1])
        np.multiply(z, inv_norm, out=out[..., 2])
        return out

    def _ray_to_pixel_block(self, xyz: np.ndarray) -> np.ndarray:
        x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
        r = x * x
        r += y * y
        np.sqrt(r, out=r)
        rho = _horner(self.inv_poly, np.arctan2(r, z))
        scale = np.divide(rho, r, out=rho, where=r > 0)
        scale[r <= 0] = 0.0
        x_o = y * scale
        y_o = x * scale
        c, d, e = self.stretch
        out = np.empty((*x.shape, 2))
        u, v = out[..., 0], out[..., 1]
        if e == 0.0:
            np.add(y_o, self.center_uv[0], out=u)
        else:
            np.multiply(x_o, e, out=u)
            u += y_o
            u += self.center_uv[0]
        np.multiply(x_o, c, out=v)
        if d != 0.0:
            y_o *= d
            v += y_o
        v += self.center_uv[1]
        return out

    def angle_from_axis(self, xyz: np.ndarray) -> np.ndarray:
        """Angle (rad) between each point's ray and the optical axis."""
        xyz = np.asarray(xyz, dtype=float)
        return np.arctan2(np.hypot(xyz[..., 0], xyz[..., 1]), xyz[..., 2])

    def in_view(self, xyz: np.ndarray) -> np.ndarray:
        """True where a ray falls within the modelled field (theta <= theta_max) and the image."""
        ok = self.angle_from_axis(xyz) <= self.theta_max
        uv = self.ray_to_pixel(xyz)
        w, h = self.image_size
        return (
            ok
            & (uv[..., 0] >= -0.5)
            & (uv[..., 0] <= w - 0.5)
            & (uv[..., 1] >= -0.5)
            & (uv[..., 1] <= h - 0.5)
        )

    def pixel_grid_rays(self, step: int = 1) -> np.ndarray:
        """Rays of every `step`-th pixel, shape (H', W', 3), for renderers and masks."""
        w, h = self.image_size
        uu, vv = np.meshgrid(np.arange(0, w, step, dtype=float), np.arange(0, h, step, dtype=float))
        return self.pixel_to_ray(np.stack([uu, vv], axis=-1))

    # ---- serialisation ----------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The model as stored in camera.json (and under `camera` in system.json)."""
        c, d, e = self.stretch
        return {
            "model": "ocam",
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "center_uv": [float(self.center_uv[0]), float(self.center_uv[1])],
            "stretch": {"c": c, "d": d, "e": e},
            "poly": [float(a) for a in self.poly],
            "inv_poly": [float(a) for a in self.inv_poly],
            "theta_max_deg": float(np.rad2deg(self.theta_max)),
            "inv_error_px": float(self.inv_error_px),
            **({"uncertainty": self.uncertainty} if self.uncertainty else {}),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "camera model") -> OcamModel:
        """Read a model dict; a missing or malformed key is an InputError naming it and `source`.

        The inverse polynomial is refitted from the forward model, which is the definition;
        the stored one is only a convenience for other tools.
        """
        if not isinstance(data, dict):
            raise InputError(f"{source}: expected a JSON object with the OCam model")
        if data.get("model", "ocam") != "ocam":
            raise InputError(f"{source}: key 'model' must be 'ocam', got {data.get('model')!r}")
        try:
            poly = [float(a) for a in data["poly"]]
            centre = (float(data["center_uv"][0]), float(data["center_uv"][1]))
            st = data["stretch"]
            stretch = (float(st["c"]), float(st["d"]), float(st["e"]))
            # Whole, finite and positive is checked by `create`, with the other values.
            size = (float(data["image_size"][0]), float(data["image_size"][1]))
        except KeyError as exc:
            raise InputError(f"{source}: missing key {exc.args[0]!r} in the camera model") from exc
        except (TypeError, ValueError, IndexError, OverflowError) as exc:
            raise InputError(f"{source}: malformed camera model ({exc})") from exc
        unc = data.get("uncertainty")
        if unc is not None and not isinstance(unc, dict):
            raise InputError(f"{source}: 'uncertainty' must be a JSON object")
        try:
            model = cls.create(poly, centre, stretch, size)
        except InputError as exc:
            raise InputError(f"{source}: {str(exc).removeprefix('camera model: ')}") from exc
        return replace(model, uncertainty=unc) if unc else model

    def ocam_inverse_for_export(self, tol_px: float = INVERSE_TOLERANCE_PX) -> np.ndarray:
        """OCamCalib's `invpol`: rho as a polynomial of t = atan(z_o / |xy|) = theta - pi/2."""
        theta = self.theta_max * 0.5 * (1 - np.cos(np.linspace(0, np.pi, 600)))
        theta_chk = np.linspace(0.0, self.theta_max, 5001)
        rho = _horner(self.inv_poly, theta)
        rho_chk = _horner(self.inv_poly, theta_chk)
        coef, _ = fit_polynomial_to_tolerance(
            theta - np.pi / 2, rho, 0.25 * tol_px, theta_chk - np.pi / 2, rho_chk
        )
        return coef
