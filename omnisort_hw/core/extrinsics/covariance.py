"""The covariance of the camera rotation and the laser plane, with the intrinsics' in it.

Two parts, kept apart because the map needs them apart:
* `noise`: the one-image fit's own: the weighted least-squares' (J^T J)^-1 (its residuals are
  divided by their measured noise and correlation), widened in every direction where the
  cluster-robust sandwich estimate is larger. Rendered targets showed why: the features'
  small systematic errors (an edge, a marker centre) leave the parameters several model
  sigmas off while the residuals stay at the noise floor everywhere but at the markers;
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
from omnisort_hw.core.frames import great_circle_normal, tangent_basis
from omnisort_hw.core.intrinsics_uncertainty import perturbed_models

N_PARAMS = len(PARAMETERS)
LINE_PIECES = 10
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


def _clusters(prob: Any, sol_x: np.ndarray) -> np.ndarray:
    """Cluster label of every residual row: each marker alone, each line in LINE_PIECES
    consecutive pieces along it (long enough to hold the few points' correlation the fit's
    inflation measures, many enough to estimate a spread)."""
    blocks = prob.residual_blocks(sol_x)
    rays = prob.line_rays()
    labels, next_label = [], 0
    for name, block in blocks.items():
        if name in rays and len(rays[name]) == len(block):
            r = rays[name]
            m = great_circle_normal(r)
            e1 = r.mean(axis=0) - (r.mean(axis=0) @ m) * m
            e1 /= np.linalg.norm(e1)
            order = np.argsort(np.arctan2(r @ np.cross(m, e1), r @ e1))
            piece = np.empty(len(block), int)
            piece[order] = np.arange(len(block)) * LINE_PIECES // max(len(block), 1)
            labels.append(next_label + piece)
            next_label += LINE_PIECES
        else:  # markers: two coordinates each, one cluster per marker
            labels.append(next_label + np.arange(len(block)) // 2)
            next_label += (len(block) + 1) // 2
    return np.concatenate(labels)


def _robust(J: np.ndarray, r: np.ndarray, labels: np.ndarray, model_cov: np.ndarray) -> np.ndarray:
    """The cluster-robust (sandwich) covariance H^-1 B H^-1, B = sum over clusters of
    (J_g^T r_g)(J_g^T r_g)^T, merged with the model's: in every direction the larger of the
    two, so the fit is never trusted more than either says (biased features that misfit the
    model show in the sandwich; a lucky small residual cannot shrink the model's)."""
    g = np.zeros((labels.max() + 1, J.shape[1]))
    np.add.at(g, labels, J * r[:, None])
    n_g = len(np.unique(labels))
    H_inv = np.linalg.pinv(J.T @ J)
    sandwich = (H_inv @ (g.T @ g) @ H_inv) * n_g / max(n_g - 1, 1)
    S = sandwich[:N_PARAMS, :N_PARAMS]
    w, V = np.linalg.eigh(model_cov)
    w = np.clip(w, 1e-30, None)
    half, half_inv = V @ np.diag(np.sqrt(w)) @ V.T, V @ np.diag(1 / np.sqrt(w)) @ V.T
    lam, U = np.linalg.eigh(half_inv @ S @ half_inv)
    return half @ U @ np.diag(np.clip(lam, 1.0, None)) @ U.T @ half


def fit_covariance(prob: Any, sol: Any, model: OcamModel) -> ExtrinsicCovariance:
    """The covariance of a finished weighted fit (`sol` of `prob`, see module docstring)."""
    J = sol.jac
    noise = np.linalg.pinv(J.T @ J)[:N_PARAMS, :N_PARAMS]
    noise = _robust(J, sol.fun, _clusters(prob, sol.x), noise)
    pairs = perturbed_models(model)
    if not pairs:
        return ExtrinsicCovariance(noise)
    step = np.linalg.pinv(J)
    modes = []
    for plus, minus in pairs:
        shifts = [-(step @ _remapped(prob, model, m).residuals(sol.x)) for m in (plus, minus)]
        modes.append(0.5 * (shifts[0] - shifts[1])[:N_PARAMS])
    return ExtrinsicCovariance(noise, np.array(modes))
