"""The result of every extrinsic method, and system.json's layout (keys shared with truth.json)."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.frames import camera_angles, camera_rotation, laser_angles, laser_normal
from omnisort_hw.errors import CalibrationError, CalibrationFileError, InputError

PARAMETERS = (
    "cam_roll_deg",
    "cam_pitch_deg",
    "cam_yaw_deg",
    "laser_roll_deg",
    "laser_pitch_deg",
    "laser_distance_mm",
)


@dataclass
class SystemCalibration:
    """Camera rotation R_SC and laser plane (normal in S, distance d below the viewpoint)."""

    model: OcamModel
    R_SC: np.ndarray
    laser_normal: np.ndarray
    laser_distance_mm: float
    method: str
    target: dict[str, Any] = field(default_factory=dict)
    residuals: dict[str, Any] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    robot_base: dict[str, Any] | None = None
    image: dict[str, Any] | None = None
    elapsed_s: float = 0.0
    # The six parameters' covariance as system.json stores it (core.extrinsics.covariance);
    # None for methods that do not give one.
    covariance: dict[str, Any] | None = None

    @classmethod
    def from_angles(
        cls, model: OcamModel, angles_deg: dict[str, float], method: str, **kw: Any
    ) -> SystemCalibration:
        r = np.radians
        R = camera_rotation(
            r(angles_deg["cam_roll_deg"]),
            r(angles_deg["cam_pitch_deg"]),
            r(angles_deg["cam_yaw_deg"]),
        )
        n = laser_normal(r(angles_deg["laser_roll_deg"]), r(angles_deg["laser_pitch_deg"]))
        return cls(model, R, n, float(angles_deg["laser_distance_mm"]), method, **kw)

    def parameters(self) -> dict[str, float]:
        """The six calibrated figures in the units of the comparison tables."""
        roll, pitch, yaw = np.degrees(camera_angles(self.R_SC))
        l_roll, l_pitch = np.degrees(laser_angles(self.laser_normal))
        return {
            "cam_roll_deg": float(roll),
            "cam_pitch_deg": float(pitch),
            "cam_yaw_deg": float(yaw),
            "laser_roll_deg": float(l_roll),
            "laser_pitch_deg": float(l_pitch),
            "laser_distance_mm": float(self.laser_distance_mm),
        }

    def to_json(self) -> dict[str, Any]:
        """system.json: the keys of the architecture note, comparable with truth.json."""
        p = self.parameters()
        out: dict[str, Any] = {
            "camera": self.model.to_dict(),
            "camera_rotation": {
                "roll_deg": p["cam_roll_deg"],
                "pitch_deg": p["cam_pitch_deg"],
                "yaw_deg": p["cam_yaw_deg"],
                "matrix": self.R_SC.tolist(),
            },
            "laser_plane": {
                "roll_deg": p["laser_roll_deg"],
                "pitch_deg": p["laser_pitch_deg"],
                "distance_mm": p["laser_distance_mm"],
                "normal": [float(x) for x in self.laser_normal],
            },
            "target": self.target,
            "method": self.method,
            "residuals": self.residuals,
            "std": self.std,
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
        }
        if self.robot_base is not None:
            out["robot_base"] = self.robot_base
        if self.image is not None:
            out["image"] = self.image
        if self.covariance is not None:
            out["covariance"] = self.covariance
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any], source: str = "system.json") -> SystemCalibration:
        """Read system.json (or truth.json); a missing or malformed key names the file and key."""
        try:
            model = OcamModel.from_dict(data["camera"], source=f"{source}: camera")
            R = np.asarray(data["camera_rotation"]["matrix"], float)
            n = np.asarray(data["laser_plane"]["normal"], float)
            d = float(data["laser_plane"]["distance_mm"])
        except KeyError as exc:
            raise CalibrationFileError(f"{source}: missing key {exc.args[0]!r}") from exc
        except (TypeError, ValueError, InputError) as exc:
            raise CalibrationFileError(f"{source}: malformed system calibration ({exc})") from exc
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise CalibrationFileError(
                f"{source}: camera_rotation.matrix must be a 3x3 matrix of finite numbers"
            )
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) < 1e-9:
            raise CalibrationFileError(
                f"{source}: laser_plane.normal must be three finite numbers, not all zero"
            )
        if not np.isfinite(d) or d <= 0:
            raise CalibrationFileError(
                f"{source}: laser_plane.distance_mm must be a positive number of mm, got {d}"
            )
        if abs(np.linalg.det(R) - 1.0) > 1e-6 or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise CalibrationFileError(f"{source}: camera_rotation.matrix is not a rotation")
        return cls(
            model=model,
            R_SC=R,
            laser_normal=n / np.linalg.norm(n),
            laser_distance_mm=d,
            method=str(data.get("method", "truth")),
            target=dict(data.get("target", {})),
            residuals=dict(data.get("residuals", {})),
            std=dict(data.get("std", {})),
            robot_base=data.get("robot_base"),
            image=data.get("image"),
            covariance=data.get("covariance"),
        )


def load_system_json(path: str | Path) -> SystemCalibration:
    """Read a system.json / truth.json file with errors that name it."""
    from omnisort_hw.fileio import read_calibration_json

    p = Path(path)
    return SystemCalibration.from_json(read_calibration_json(p, "system"), source=str(p))


def place_side_walls(
    R_SC: np.ndarray, m_left: np.ndarray, m_right: np.ndarray, separation_mm: float
) -> tuple[float, float]:
    """X of the left wall and Z of the border line from the two borders' great-circle normals
    (in C): in S a border X = x_w, Z = z_b along Y has normal ~ (-z_b, 0, x_w), so each gives
    z_b / x_w; the known separation sets the scale. Raises if the walls are not seen apart."""
    k = []
    for m in (m_left, m_right):
        mS = R_SC @ m
        k.append(-mS[0] / mS[2])
    if abs(k[0] - k[1]) < 1e-9:
        raise CalibrationError("border lines are degenerate (walls not seen apart)")
    x_left = k[1] * separation_mm / (k[0] - k[1])
    return float(x_left), float(k[0] * x_left)


def fit_laser_plane(points_S: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Least-squares plane through 3D points in S: (upward unit normal, distance d of the
    docs/frames.md convention, i.e. the plane meets the Z axis at -d, RMS distance in mm)."""
    centroid = points_S.mean(axis=0)
    _, _, vt = np.linalg.svd(points_S - centroid, full_matrices=False)
    n = vt[-1] if vt[-1][2] > 0 else -vt[-1]
    rms = float(np.sqrt(np.mean(((points_S - centroid) @ n) ** 2)))
    return n, float(-(n @ centroid) / n[2]), rms


def pixel_scale(model: OcamModel, rays_C: np.ndarray) -> np.ndarray:
    """Pixels per radian of a small angle at each ray (d rho / d theta of the inverse model),
    used to express angular residuals as image pixels, where the noise is."""
    theta = model.angle_from_axis(rays_C)
    deriv = np.polynomial.polynomial.polyder(model.inv_poly)
    return np.abs(np.polynomial.polynomial.polyval(theta, deriv))
