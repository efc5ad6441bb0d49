"""The device sections `[camera]`, `[laser]` and `[arm]` of the cell configuration (TOML).

Each section names its `backend` and the backend's settings:

    [camera]  backend = "v4l2"     -> drivers.v4l2_camera.V4L2CameraConfig
    [laser]   backend = "serial"   -> drivers.serial_laser.SerialLaserConfig
              backend = "modbus"   -> drivers.modbus_laser.ModbusLaserConfig
    [arm]     backend = "ur_rtde"  -> drivers.ur_arm.URArmConfig
    any       backend = "sim"      -> the other keys are passed as a dict to sim_backend

Real backends are checked key by key against their config dataclass: an unknown key, a missing
required key, a value of the wrong type or out of range raises `ConfigError` whose message
starts with the key (`[laser].baudrate: ...`) and which carries it as `.key`. A section left
out means the cell has no such device (None). Other sections ([service], ...) are ignored here.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from drivers.errors import DeviceConfigError
from drivers.modbus_laser import ModbusLaserConfig
from drivers.serial_laser import SerialLaserConfig
from drivers.ur_arm import URArmConfig
from drivers.v4l2_camera import V4L2CameraConfig
from omnisort_hw.core.choices import LASER_COLORS
from omnisort_hw.errors import ConfigError
from omnisort_hw.wire_records import WireError, read_value

DeviceKind = Literal["camera", "laser", "arm"]
DEVICE_SECTIONS: tuple[DeviceKind, ...] = ("camera", "laser", "arm")
SIM_BACKEND = "sim"

BACKENDS: dict[str, dict[str, type]] = {
    "camera": {"v4l2": V4L2CameraConfig},
    "laser": {"serial": SerialLaserConfig, "modbus": ModbusLaserConfig},
    "arm": {"ur_rtde": URArmConfig},
}


# The simulated devices' settings (sim_backend.devices.open_devices documents them); checked
# when the cell file loads, so a typo stops the start, not the first grab.
SIM_SETTINGS: dict[str, dict[str, type]] = {
    "camera": {
        "scene": str,
        "seed": int,
        "degraded": bool,
        "width": int,
        "height": int,
        "model_file": str,
        "exposure_ms": float,
        "gain": float,
        "grab_timeout_s": float,
        "bump_deg": float,
        "bump_axis": str,
        "bump_after_grabs": int,
        "pixel_format": str,
        "lighting": str,
    },
    "laser": {"scene": str, "seed": int},
    "arm": {
        "scene": str,
        "seed": int,
        "joint_speed_deg_s": float,
        "joint_accel_deg_s2": float,
        "linear_speed_mm_s": float,
        "linear_accel_mm_s2": float,
        "max_joint_speed_deg_s": float,
        "max_joint_accel_deg_s2": float,
        "max_linear_speed_mm_s": float,
        "max_linear_accel_mm_s2": float,
        "realtime": bool,
    },
}


# Numeric settings that may be zero or negative; every other one must be positive.
SIM_SIGNED = frozenset({"seed", "bump_deg", "bump_after_grabs"})


def check_sim_settings(kind: str, settings: Mapping[str, object]) -> dict[str, Any]:
    """A `backend = "sim"` section's settings with their TOML types checked (ints accepted
    for floats), or a ConfigError naming `[kind].key`."""
    allowed = SIM_SETTINGS.get(kind)
    if allowed is None:
        raise config_error(f"[{kind}].backend", f'no simulated "{kind}" device')
    out: dict[str, Any] = {}
    for key, value in settings.items():
        if key not in allowed:
            raise config_error(
                f"[{kind}].{key}",
                f"unknown key for the simulated {kind} (known: {', '.join(sorted(allowed))})",
            )
        tp = allowed[key]
        value = _convert(tp, value, f"[{kind}].{key}")  # the real backends' TOML types
        if tp in (int, float) and key not in SIM_SIGNED and not value > 0:
            raise config_error(f"[{kind}].{key}", f"must be positive, got {value!r}")
        out[key] = value
    return out


def config_error(key: str, message: str) -> ConfigError:
    """A `ConfigError` whose message starts with `key` and which carries it as `.key`."""
    err = ConfigError(f"{key}: {message}")
    err.key = key  # type: ignore[attr-defined]
    return err


@dataclass(frozen=True)
class DeviceSection:
    """One device section: which backend, and its settings.

    `settings` is the backend's typed config dataclass for a real backend, and a plain dict
    (every key but `backend`) for `backend = "sim"`.
    """

    kind: DeviceKind
    backend: str
    settings: Any
    color: str = "red"  # the laser's light (`[laser] color`, any backend): what the
    # stripe extractor looks for (core.laser_stripe.as_red_laser)

    @property
    def is_sim(self) -> bool:
        return self.backend == SIM_BACKEND


@dataclass(frozen=True)
class CellDeviceConfig:
    """The device sections of one cell file; a section that is absent is None."""

    camera: DeviceSection | None = None
    laser: DeviceSection | None = None
    arm: DeviceSection | None = None
    base_dir: Path | None = None

    def sections(self) -> list[tuple[DeviceKind, DeviceSection | None]]:
        return [("camera", self.camera), ("laser", self.laser), ("arm", self.arm)]

    @property
    def laser_color(self) -> str:
        """The laser's colour (red without a `[laser]`, and by default)."""
        return self.laser.color if self.laser is not None else "red"


def _convert(tp: Any, value: object, key: str) -> Any:
    """`value` checked against the annotation `tp` (TOML types), converted where lossless
    (an integer for a number, a list for a tuple): the replies' codec, a ConfigError naming
    `key`."""
    try:
        return read_value(tp, value, key)
    except WireError as exc:
        raise config_error(exc.path, exc.problem) from None


def build_config(cls: type, section: str, data: Mapping[str, object]) -> Any:
    """Instantiate the config dataclass `cls` from `data`, naming `[section].key` on any error."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise config_error(
            f"[{section}].{unknown[0]}",
            f"unknown key for this backend (known: {', '.join(sorted(fields))})",
        )
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        key = f"[{section}].{name}"
        if name not in data:
            no_default = f.default is dataclasses.MISSING
            if no_default and f.default_factory is dataclasses.MISSING:
                raise config_error(key, "missing (this backend requires it)")
            continue
        kwargs[name] = _convert(hints[name], data[name], key)
    try:
        return cls(**kwargs)
    except DeviceConfigError as exc:
        message = str(exc).removeprefix(f"{exc.key}: ")
        raise config_error(exc.key, message) from None


def parse_device_section(
    kind: DeviceKind, data: object, base_dir: Path | None = None
) -> DeviceSection:
    """One `[camera]` / `[laser]` / `[arm]` table -> `DeviceSection`."""
    if not isinstance(data, Mapping):
        raise config_error(f"[{kind}]", "must be a table")
    backend = data.get("backend")
    known = sorted([*BACKENDS[kind], SIM_BACKEND])
    if backend is None:
        raise config_error(f"[{kind}].backend", f"missing; one of {', '.join(known)}")
    if backend not in known:
        raise config_error(
            f"[{kind}].backend", f"unknown backend {backend!r}; one of {', '.join(known)}"
        )
    settings = {k: v for k, v in data.items() if k != "backend"}
    color = "red"
    if kind == "laser" and "color" in settings:
        given = settings.pop("color")
        if not isinstance(given, str) or given not in LASER_COLORS:
            raise config_error(
                "[laser].color", f"{given!r} is not one of {', '.join(LASER_COLORS)}"
            )
        color = given
    if backend == SIM_BACKEND:
        return DeviceSection(kind, backend, check_sim_settings(kind, settings), color)
    if kind == "camera" and base_dir is not None:
        settings = _resolve_camera_file(settings, base_dir)
    return DeviceSection(
        kind, backend, build_config(BACKENDS[kind][backend], kind, settings), color
    )


def _resolve_camera_file(settings: dict[str, Any], base_dir: Path) -> dict[str, Any]:
    """A recorded source (api ffmpeg/images) and a measured tone-curve table (a .json file)
    given relative to the config file's folder."""
    out = dict(settings)
    device = settings.get("device")
    if settings.get("api") in ("ffmpeg", "images") and isinstance(device, str):
        path = Path(device).expanduser()
        if not path.is_absolute():
            out["device"] = str(base_dir / path)
    tone = settings.get("tone_curve")
    if isinstance(tone, str) and tone.lower().endswith(".json"):
        path = Path(tone).expanduser()
        if not path.is_absolute():
            out["tone_curve"] = str(base_dir / path)
    return out


def parse_device_config(
    doc: Mapping[str, object], base_dir: Path | None = None
) -> CellDeviceConfig:
    """The device sections of an already parsed cell document (other sections are ignored)."""
    found: dict[str, DeviceSection] = {}
    for kind in DEVICE_SECTIONS:
        if kind in doc:
            found[kind] = parse_device_section(kind, doc[kind], base_dir)
    return CellDeviceConfig(**found, base_dir=base_dir)


__all__ = [
    "BACKENDS",
    "DEVICE_SECTIONS",
    "CellDeviceConfig",
    "DeviceSection",
    "build_config",
    "check_sim_settings",
    "config_error",
    "parse_device_config",
    "parse_device_section",
]
