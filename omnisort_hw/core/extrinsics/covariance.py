"""The covariance of the camera rotation and the laser plane, with the intrinsics' in it.

Two parts, kept apart because the map needs them apart:
* `noise`: the one-image fit's own (the weighted least-squares' (J^T J)^-1: its residuals are
  divided by their measured noise and correlation, so it needs no rescaling);
* `modes`: for each principal direction of the intrinsics' covariance (camera.json carries it
  with the model), the shift of the six parameters that one sigma of it causes, found by one
  Gauss-Newton step of the same fit on the observations re-unprojected through the perturbed
  model. The map re-unprojects its pixels through the same perturbed model, so the part of an
  intrinsic error that the extrinsics absorb (a shifted centre looks like a turned camera)
  cancels in a map point as it does in reality; adding the modes' covariance to `noise`
  without that correlation would count it twice.

Parameters: PARAMETERS (camera roll, pitch, yaw, laser roll, pitch in radians inside, degrees
in system.json; laser distance in mm).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS
from omnisort_hw.core.frames import tangent_basis
from omnisort_hw.core.intrinsics_uncertainty import perturbed_models

N_PARAMS = len(PARAMETERS)
_TO_FILE = np.array([*np.full(5, np.degrees(1.0)), 1.0])  # radians -> degrees, mm stays


@dataclass
class ExtrinsicCovariance:
    """Covariance of the six parameters (radians, mm) from the image noise, and the shift
    of each per one-sigma intrinsic mode (K, 6), in the order `perturbed_models` gives."""

    noise: np.ndarray
    modes: np.ndarray = field(default_factory=lambda: np.zeros((0, N_PARAMS)))

    @property
    def total(self) -> np.ndarray:
        return self.noise + self.modes.T @ self.modes

    def std(self) -> dict[str, float]:
        """Every parameter's standard deviation, all sources (degrees, mm)."""
        s = np.sqrt(np.clip(np.diag(self.total), 0.0, None)) * _TO_FILE
        return {name: float(v) for name, v in zip(PARAMETERS, s, strict=True)}

    def to_json(self) -> dict[str, Any]:
        scale = np.outer(_TO_FILE, _TO_FILE)
        return {
            "parameters": list(PARAMETERS),
            "units": "degrees and mm",
            "noise": (self.noise * scale).tolist(),
            "intrinsics_modes": (self.modes * _TO_FILE).tolist(),
            "total": (self.total * scale).tolist(),
            "std_all_sources": self.std(),
        }

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> ExtrinsicCovariance:
        scale = np.outer(_TO_FILE, _TO_FILE)
        noise = np.asarray(data["noise"], float).reshape(N_PARAMS, N_PARAMS) / scale
        modes = np.asarray(data.get("intrinsics_modes", []), float).reshape(-1, N_PARAMS)
        return cls(noise, modes / _TO_FILE)


def _remapped(prob: Any, model: OcamModel, other: OcamModel) -> Any:
    """A copy of the problem whose observed rays went through `other` instead of `model`
    (back to their pixels through `model`, forward through `other`)."""
    q = copy.deepcopy(prob)
    for rays, _, key in q.line_store().values():
        if len(rays[key]):
            rays[key] = other.pixel_to_ray(model.ray_to_pixel(rays[key]))
    if hasattr(q, "marker_rays"):
        q.marker_rays = other.pixel_to_ray(model.ray_to_pixel(q.marker_rays))
        q.marker_basis = tangent_basis(q.marker_rays)
    return q


def fit_covariance(prob: Any, sol: Any, model: OcamModel) -> ExtrinsicCovariance:
    """The covariance of a finished weighted fit (`sol` of `prob`, see module docstring)."""
    J = sol.jac
    noise = np.linalg.pinv(J.T @ J)[:N_PARAMS, :N_PARAMS]
    pairs = perturbed_models(model)
    if not pairs:
        return ExtrinsicCovariance(noise)
    step = np.linalg.pinv(J)
    modes = []
    for plus, minus in pairs:
        shifts = [-(step @ _remapped(prob, model, m).residuals(sol.x)) for m in (plus, minus)]
        modes.append(0.5 * (shifts[0] - shifts[1])[:N_PARAMS])
    return ExtrinsicCovariance(noise, np.array(modes))
