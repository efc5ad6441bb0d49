"""A located cube's position uncertainty, every known source, and whether the gripper can
take it.

The outline fit gives the centre's covariance from the image (`Cube.fit_cov_xy`). The
calibration adds its own: the camera rotation's covariance (system.json's `covariance`,
core.extrinsics.covariance) moves the ray through the cube's top centre, which meets the
cube's top plane elsewhere; each principal direction of that 3x3 block is applied at +-1 sigma
and the two intersections differenced (the laser plane does not enter: the centre comes from
the outline). Both are along B's x and y, in mm^2.

A pick is safe when the centre's 95 % error ellipse fits the gripper's capture tolerance
(how far off centre the open jaws still close on the cube): its largest semi-axis,
sqrt(chi2_2(0.95) lambda_max), must not exceed it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from omnisort_hw.core.cube_location import Cube, FloorGeometry
from omnisort_hw.core.extrinsics.covariance import ExtrinsicCovariance
from omnisort_hw.core.frames import camera_rotation

CHI2_2_95 = 5.991465  # chi-square quantile, 2 degrees of freedom, 95 %
UNCERTAIN = "position uncertain"  # the reason's prefix: the typed reason of a refused pick


def rotation_covariance(covariance: dict[str, Any] | None) -> np.ndarray | None:
    """The camera angles' 3x3 covariance (rad^2), all sources, from system.json's record."""
    if not covariance:
        return None
    return ExtrinsicCovariance.from_json(covariance).total[:3, :3]


def add_calibration_part(
    cubes: Sequence[Cube],
    R_SC: np.ndarray,
    angles_rad: np.ndarray,
    T_SB: np.ndarray,
    size_mm: float,
    floor_z_B_mm: float,
    rot_cov: np.ndarray | None,
) -> None:
    """Set every cube's `position_cov_xy`: the fit's covariance plus the camera rotation's
    part (none when `rot_cov` is None). `angles_rad` are R_SC's roll, pitch, yaw."""
    geom = FloorGeometry(np.asarray(T_SB, float), floor_z_B_mm)
    for cube in cubes:
        fit = (
            cube.fit_cov_xy if cube.fit_cov_xy is not None else np.diag(np.square(cube.sigma_xy_mm))
        )
        cov = np.array(fit, float)
        if rot_cov is not None:
            top = cube.center_S + 0.5 * size_mm * geom.normal_S
            ray_C = R_SC.T @ top
            w, V = np.linalg.eigh(0.5 * (rot_cov + rot_cov.T))
            for lam, v in zip(w, V.T, strict=True):
                if lam <= 0:
                    continue
                s = np.sqrt(lam) * v
                ends = [
                    geom.to_plane((camera_rotation(*(angles_rad + k * s)) @ ray_C)[None], size_mm)[
                        0
                    ]
                    for k in (1.0, -1.0)
                ]
                dxy = 0.5 * (ends[0][0] - ends[1][0])
                cov += np.outer(dxy, dxy)
        cube.position_cov_xy = cov


def capture_radius_mm(cube: Cube) -> float:
    """The largest semi-axis (mm) of the centre's 95 % error ellipse."""
    cov = cube.position_cov_xy if cube.position_cov_xy is not None else cube.fit_cov_xy
    if cov is None:
        cov = np.diag(np.square(cube.sigma_xy_mm))
    lam = float(np.max(np.linalg.eigvalsh(0.5 * (cov + cov.T))))
    return float(np.sqrt(CHI2_2_95 * max(lam, 0.0))) if np.isfinite(lam) else float("inf")


def capture_refusal(cube: Cube, tolerance_mm: float) -> str | None:
    """Why the gripper cannot be trusted to take the cube (None when it can)."""
    r = capture_radius_mm(cube)
    if r <= tolerance_mm:
        return None
    return (
        f"{UNCERTAIN}: 95 % error radius {r:.1f} mm exceeds the gripper's capture tolerance "
        f"{tolerance_mm:g} mm"
    )
