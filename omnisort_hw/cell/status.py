"""What each device reports for `status`: plain summaries of one read, and the cache records
the cell keeps them in (so `status` never waits on a device)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class Cached:
    """One value and when it was read (monotonic seconds)."""

    value: Any = None
    at: float = -1e18

    def fresh(self, max_age_s: float) -> bool:
        return time.monotonic() - self.at <= max_age_s


@dataclass
class Caches:
    """The cell's cached device and calibration reads."""

    arm: Cached = field(default_factory=Cached)
    laser: Cached = field(default_factory=Cached)
    calibration: Cached = field(default_factory=Cached)
    calibration_key: Any = None


def error_text(exc: BaseException) -> dict[str, str]:
    """A device error as status fields: its message and its typed code."""
    return {"error": str(exc), "code": str(getattr(exc, "code", type(exc).__name__))}


def arm_summary(arm: Any) -> dict[str, Any]:
    """The arm's connection, joints, TCP pose and safety state, read once."""
    out: dict[str, Any] = {"configured": True, "name": arm.name, "connected": arm.is_connected}
    if arm.is_connected:
        try:
            st = arm.state()
            out.update(
                joints_deg=np.round(np.asarray(st.joints_deg, float), 4).tolist(),
                tcp_pose=np.round(np.asarray(st.tcp_pose, float), 4).tolist(),
                safety={
                    "ok": st.safety.ok,
                    "protective_stop": st.safety.protective_stop,
                    "emergency_stop": st.safety.emergency_stop,
                    "robot_mode": st.safety.robot_mode,
                    "safety_mode": getattr(st.safety, "safety_mode", None),
                },
            )
        except Exception as exc:
            out.update(error_text(exc))
    return out


def camera_summary(cam: Any) -> dict[str, Any]:
    """The camera's connection, serial and resolution (no frame is grabbed)."""
    if cam is None:
        return {"configured": False}
    out: dict[str, Any] = {"configured": True, "name": cam.name, "connected": cam.is_connected}
    if cam.is_connected:
        try:
            out["serial"] = cam.serial
            out["resolution"] = list(cam.resolution)
        except Exception as exc:
            out.update(error_text(exc))
    return out
