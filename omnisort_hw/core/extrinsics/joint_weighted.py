"""What both targets' `joint` refinements share: residual blocks weighted by each kind's
measured noise and by the correlation of neighbouring line points, stray points dropped, and
the covariance of the maximum-likelihood fit (`joint`, `joint_three_sided`)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS
from omnisort_hw.core.frames import great_circle_normal
from omnisort_hw.core.residual_correlation import correlation_inflation


def _order_along(rays: np.ndarray) -> np.ndarray:
    """Indices that sort rays lying near one great circle along it."""
    m = great_circle_normal(rays)
    e1 = rays.mean(axis=0)
    e1 -= (e1 @ m) * m
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(m, e1)
    return np.argsort(np.arctan2(rays @ e2, rays @ e1))


def line_inflation(blocks: dict[str, np.ndarray], rays: dict[str, np.ndarray]) -> dict[str, float]:
    """Per kind of line observation, the point-weighted mean of its lines' inflations."""
    acc: dict[str, list[tuple[float, int]]] = {}
    for name, ray in rays.items():
        if len(ray) == 0:
            continue
        f = correlation_inflation(blocks[name][_order_along(ray)])
        acc.setdefault(name.split("_")[0], []).append((f, len(ray)))
    return {k: sum(f * n for f, n in v) / sum(n for _, n in v) for k, v in acc.items()}


# Block name -> (the dict holding its rays, the dict holding their pixel scales, its key).
LineStore = dict[str, tuple[dict[str, np.ndarray], dict[str, np.ndarray], str]]


class _WeightedProblem:
    """What both targets' problems share: residual blocks named "<kind>_<line>", each kind
    weighted by its measured noise and correlation, stray line points dropped. Subclasses give
    `residual_blocks(p)` and `line_store()` (block name -> (rays dict, scales dict, key))."""

    weights: dict[str, float]
    inflation: dict[str, float]

    def residual_blocks(self, p: np.ndarray) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def line_store(self) -> LineStore:
        raise NotImplementedError

    def line_rays(self) -> dict[str, np.ndarray]:
        """The observed rays behind each line block of `residual_blocks` (for their order)."""
        return {name: rays[key] for name, (rays, _, key) in self.line_store().items()}

    def residuals(self, p: np.ndarray) -> np.ndarray:
        """Weighted residuals: each kind divided by its noise, so the sum is the likelihood."""
        return np.concatenate(
            [
                block * self.weights[name.split("_")[0]]
                for name, block in self.residual_blocks(p).items()
            ]
        )

    def noise_px(self, p: np.ndarray) -> dict[str, float]:
        """Robust noise estimate (px) of each kind of observation at parameters p: 1.4826 MAD
        for the line points, RMS for the few marker coordinates; floored at 0.02 px."""
        kinds: dict[str, list[np.ndarray]] = {}
        for name, block in self.residual_blocks(p).items():
            kinds.setdefault(name.split("_")[0], []).append(block)
        out = {}
        for kind, blocks in kinds.items():
            r = np.concatenate(blocks)
            sigma = np.sqrt(np.mean(r**2)) if kind == "markers" else 1.4826 * np.median(np.abs(r))
            out[kind] = max(float(sigma), 0.02)
        return out

    def estimate_weights(self, p: np.ndarray) -> dict[str, float]:
        """Weight each kind by 1 / (noise * sqrt(inflation)): neighbouring line points share
        pixels (overlapping fit windows, blur), so N of them carry less than N independent
        measurements; the inflation is measured from the residuals' correlation along each
        line, which keeps the kinds' relative weights and the covariance honest."""
        noise = self.noise_px(p)
        self.inflation = line_inflation(self.residual_blocks(p), self.line_rays())
        self.weights.update(
            {k: 1.0 / (v * np.sqrt(self.inflation.get(k, 1.0))) for k, v in noise.items()}
        )
        return noise

    def reject_outliers(self, p: np.ndarray, k: float = 4.0) -> int:
        """Drop line points further than k noise sigmas of their kind from the fit (stray
        extracted points), keeping at least 5 a line; markers are kept (each one is needed)."""
        noise = self.noise_px(p)
        blocks = self.residual_blocks(p)
        dropped = 0
        for name, (rays, scale, key) in self.line_store().items():
            keep = np.abs(blocks[name]) <= k * noise[name.split("_")[0]]
            if not keep.all() and keep.sum() >= 5:
                rays[key], scale[key] = rays[key][keep], scale[key][keep]
                dropped += int((~keep).sum())
        return dropped


def _refine(prob: _WeightedProblem, x0: np.ndarray) -> tuple[OptimizeResult, dict[str, float]]:
    """LM from x0, then twice: drop points beyond 4 sigmas of their kind, weight each kind by
    its measured noise and correlation, solve again. Returns the solution and the noise."""
    sol = least_squares(prob.residuals, x0, method="lm", x_scale="jac", max_nfev=400)
    noise: dict[str, float] = {}
    for _ in range(2):
        prob.reject_outliers(sol.x)
        noise = prob.estimate_weights(sol.x)
        sol = least_squares(prob.residuals, sol.x, method="lm", x_scale="jac", max_nfev=400)
    return sol, noise


def _outcome(
    prob: _WeightedProblem, sol: OptimizeResult, noise: dict[str, float]
) -> tuple[np.ndarray, dict[str, Any], dict[str, float]]:
    """What both targets report of a refinement: every parameter's standard deviation, the
    residual summary, and the std record of the parameters they share (degrees, mm). The
    residuals are weighted by their measured noise and correlation, so the covariance of the
    maximum-likelihood fit is (J^T J)^-1 without rescaling."""
    std = np.sqrt(np.clip(np.diag(np.linalg.pinv(sol.jac.T @ sol.jac)), 0.0, None))
    blocks = prob.residual_blocks(sol.x)
    residuals = {
        "rms_px": float(np.sqrt(np.mean(np.concatenate(list(blocks.values())) ** 2))),
        **{f"{k}_rms_px": float(np.sqrt(np.mean(v**2))) for k, v in blocks.items()},
        "noise_px": noise,
        "correlation_inflation": dict(prob.inflation),
        "observations": int(sol.fun.size),
    }
    record = {
        **{PARAMETERS[i]: float(np.degrees(std[i])) for i in range(5)},
        PARAMETERS[5]: float(std[5]),
        "border_z_mm": float(std[7]),
        "wall_left_x_mm": float(std[6]),
    }
    return std, residuals, record
