"""Device factory: the cell configuration's `backend` picks the driver class.

`open_camera`, `open_laser` and `open_arm` build the device for one `DeviceSection` and return
it NOT yet connected (use `with device:` or `device.connect()`), so building never blocks and
the caller decides when to touch the hardware. `open_devices` builds all three from a parsed
cell document (what `omnisort_hw.cell.devices.open_devices` reads).

`backend = "sim"` is delegated to the simulated cell, imported lazily because it pulls in
pybullet. Its contract (implemented in `sim_backend/devices.py`):

    def open_devices(
        sections: dict[str, dict[str, Any]], base_dir: Path | None
    ) -> dict[str, Device]: ...

`sections` maps "camera" / "laser" / "arm" (only those whose backend is "sim") to their settings
(every key of the section but `backend`); the result maps the same names to unconnected
`drivers.base` devices. All sim devices of a cell are requested in one call so they can share
one simulated world. `sim_backend/device_proxies.py` implements the same contract with the
world in a child process (`open_devices(..., in_child=True)`, what the service uses).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drivers.base import Arm, Camera, Device, LaserSwitch
from drivers.errors import DeviceError
from omnisort_hw.cell.status import error_text
from omnisort_hw.config.devices import (
    CellDeviceConfig,
    DeviceKind,
    DeviceSection,
    config_error,
    parse_device_config,
)
from omnisort_hw.pipeline.replies import DeviceError as ReplyDeviceError

if TYPE_CHECKING:
    from omnisort_hw.pipeline.sort import SceneLayout


@dataclass
class Devices:
    """The cell's devices, unconnected; a device without a section is None. `scene` is the
    cell's layout and truth when the backend knows them (the simulated cell; None for real
    devices): `[sorting] from_scene` and the verification of a sort use it."""

    camera: Camera | None = None
    laser: LaserSwitch | None = None
    arm: Arm | None = None
    scene: SceneLayout | None = None

    def items(self) -> list[tuple[str, Device | None]]:
        return [("camera", self.camera), ("laser", self.laser), ("arm", self.arm)]

    def reconnect_lost(self) -> tuple[list[str], dict[str, ReplyDeviceError]]:
        """Connect again every device that is no longer connected (the operator's reset after
        a fault): the ones that came back, and the ones still lost with their typed error."""
        back: list[str] = []
        lost: dict[str, ReplyDeviceError] = {}
        for kind, dev in self.items():
            if dev is None or dev.is_connected:
                continue
            try:
                dev.connect()
                back.append(kind)
            except DeviceError as exc:
                lost[kind] = ReplyDeviceError(**error_text(exc))
        return back, lost


def _open_sim(
    sections: Mapping[DeviceKind, DeviceSection], base_dir: Path | None, in_child: bool = False
) -> tuple[dict[str, Any], SceneLayout | None]:
    """Build the `backend = "sim"` devices through `sim_backend.devices.open_devices` (or, with
    `in_child`, `sim_backend.device_proxies.open_devices`: the same devices in a child process),
    and the simulated cell's scene for the sorting pipeline."""
    first = next(iter(sections))
    key = f"[{first}].backend"
    try:
        if in_child:
            from sim_backend import device_proxies as sim_devices
        else:
            from sim_backend import devices as sim_devices  # type: ignore[no-redef]
    except ImportError as exc:
        raise config_error(
            key,
            f'"sim" needs the simulated cell (sim_backend.devices), which cannot be imported '
            f"here ({exc}); use a real backend or install the full build",
        ) from None
    factory = getattr(sim_devices, "open_devices", None)
    if factory is None:
        raise config_error(key, "sim_backend.devices has no open_devices() in this build")
    made = factory({k: dict(s.settings) for k, s in sections.items()}, base_dir)
    missing = sorted(set(sections) - set(made))
    if missing:
        raise config_error(f"[{missing[0]}].backend", "the simulated cell did not provide it")
    from sim_backend.sort_harness import scene_of

    return dict(made), scene_of(made)


def _open_real(section: DeviceSection) -> Device:
    kind, backend, cfg = section.kind, section.backend, section.settings
    if kind == "camera" and backend == "v4l2":
        from drivers.v4l2_camera import V4L2Camera

        return V4L2Camera(cfg)
    if kind == "laser" and backend == "serial":
        from drivers.serial_laser import SerialLaser

        return SerialLaser(cfg)
    if kind == "laser" and backend == "modbus":
        from drivers.modbus_laser import ModbusLaser

        return ModbusLaser(cfg)
    if kind == "arm" and backend == "ur_rtde":
        from drivers.ur_arm import URArm

        return URArm(cfg)
    raise config_error(f"[{kind}].backend", f"no driver for backend {backend!r}")


def _open_one(section: DeviceSection, base_dir: Path | None) -> Device:
    if section.is_sim:
        return _open_sim({section.kind: section}, base_dir)[0][section.kind]
    return _open_real(section)


def open_camera(section: DeviceSection, base_dir: Path | None = None) -> Camera:
    """The camera of a `[camera]` section (unconnected)."""
    device = _open_one(section, base_dir)
    if not isinstance(device, Camera):
        raise config_error("[camera].backend", f"{type(device).__name__} is not a Camera")
    return device


def open_laser(section: DeviceSection, base_dir: Path | None = None) -> LaserSwitch:
    """The laser switch of a `[laser]` section (unconnected)."""
    device = _open_one(section, base_dir)
    if not isinstance(device, LaserSwitch):
        raise config_error("[laser].backend", f"{type(device).__name__} is not a LaserSwitch")
    return device


def open_arm(section: DeviceSection, base_dir: Path | None = None) -> Arm:
    """The arm of an `[arm]` section (unconnected)."""
    device = _open_one(section, base_dir)
    if not isinstance(device, Arm):
        raise config_error("[arm].backend", f"{type(device).__name__} is not an Arm")
    return device


def open_devices(
    config: Mapping[str, object] | CellDeviceConfig,
    config_path: Path | None = None,
    in_child: bool = False,
) -> Devices:
    """All devices of a cell (unconnected). `config` is the parsed TOML document or its
    device sections; relative paths resolve against `config_path`'s folder. `in_child`: devices
    that would compute in the caller's process (the simulated cell's rendering and physics) run
    in a child process behind proxies instead (the service asks for it; real drivers are not
    affected)."""
    if isinstance(config, CellDeviceConfig):
        cell = config
    else:
        base = config_path.resolve().parent if config_path is not None else None
        cell = parse_device_config(config, base)
    present = {k: s for k, s in cell.sections() if s is not None}
    sim = {k: s for k, s in present.items() if s.is_sim}
    made, scene = _open_sim(sim, cell.base_dir, in_child) if sim else ({}, None)
    for kind, section in present.items():
        if not section.is_sim:
            made[kind] = _open_real(section)
    expected = {"camera": Camera, "laser": LaserSwitch, "arm": Arm}
    for name, device in made.items():
        if not isinstance(device, expected[name]):
            raise config_error(
                f"[{name}].backend", f"{type(device).__name__} is not a {expected[name].__name__}"
            )
    return Devices(made.get("camera"), made.get("laser"), made.get("arm"), scene)


__all__ = ["Devices", "open_arm", "open_camera", "open_devices", "open_laser"]
