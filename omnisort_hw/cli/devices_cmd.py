"""`omnisort devices list|check` and `omnisort laser on|off|state`.

* `devices list`: the cameras (`/dev/video*`, name, capture formats) and serial ports attached.
* `devices check --config cell.toml`: opens each configured device, exercises it once (a frame,
  the laser state, the arm's safety status and joints), prints a table and exits 1 if any
  device failed. Every step is bounded by the device's own timeouts.
* `laser on|off|state --config cell.toml`: switch the laser (confirmed by read-back) or read it.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from omnisort_hw.cli.arg_types import Subcommands
from omnisort_hw.cli.output import print_result

if TYPE_CHECKING:  # a command's --help stays quick
    from drivers.base import Device
    from omnisort_hw.config.devices import DeviceSection

EXIT_DEVICE_FAILED = 1


def register(sub: Subcommands) -> None:
    devices = sub.add_parser("devices", help="list attached devices or check the configured ones")
    dsub = devices.add_subparsers(dest="devices_command", required=True, metavar="ACTION")
    p_list = dsub.add_parser("list", help="cameras and serial ports attached to this PC")
    p_list.add_argument("--json", action="store_true", help="print JSON instead of text")
    p_list.set_defaults(func=run_list)
    p_check = dsub.add_parser(
        "check", help="open each device of a cell configuration and report its status"
    )
    p_check.add_argument("--config", type=Path, required=True, help="the cell TOML file")
    p_check.add_argument(
        "--only", choices=("camera", "laser", "arm"), action="append", help="check only these"
    )
    p_check.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p_check.set_defaults(func=run_check)

    laser = sub.add_parser("laser", help="switch the laser line on or off, or read its state")
    laser.add_argument("action", choices=("on", "off", "state"))
    laser.add_argument("--config", type=Path, required=True, help="the cell TOML file")
    laser.set_defaults(func=run_laser)


def run_list(args: argparse.Namespace) -> int:
    from drivers.discovery import list_cameras, list_serial_ports

    cameras, ports = list_cameras(), list_serial_ports()
    if args.json:
        print_result(
            {"cameras": [asdict(c) for c in cameras], "serial_ports": [asdict(p) for p in ports]},
            indent=2,
        )
        return 0
    print("Cameras:")
    for cam in cameras:
        print(f"  {cam.describe()}")
    if not cameras:
        print("  none (/dev/video* is empty: is the camera plugged in?)")
    print("Serial ports:")
    for port in ports:
        print(f"  {port.describe()}")
    if not ports:
        print("  none")
    return 0


@dataclass
class CheckRow:
    """One line of the `devices check` table."""

    device: str
    backend: str
    where: str
    ok: bool
    status: str
    detail: str
    seconds: float


def _where(section: DeviceSection) -> str:
    cfg = section.settings
    if section.is_sim:
        return "simulated"
    for attr in ("where", "device", "port", "host"):
        value = getattr(cfg, attr, None)
        if value:
            return str(value)
    return "?"


def _exercise(device: Device) -> str:
    """Touch the device once and describe what it answered."""
    from drivers.base import Arm, Camera, LaserSwitch

    if isinstance(device, Camera):
        frame = device.grab()
        h, w = frame.image.shape[:2]
        return f"frame {w}x{h}, serial {device.serial}"
    if isinstance(device, LaserSwitch):
        return f"laser is {'ON' if device.state() else 'OFF'}"
    if not isinstance(device, Arm):
        raise TypeError(f"{type(device).__name__} is not a camera, a laser or an arm")
    status = device.safety_status()
    q = device.joint_positions()
    joints = ", ".join(f"{v:.1f}" for v in q)
    stop = "" if status.ok else " STOPPED"
    return f"{status.robot_mode}/{status.safety_mode}{stop}, joints [{joints}] deg"


def check_devices(config_path: Path, only: list[str] | None = None) -> list[CheckRow]:
    """Open, exercise and close each configured device; never raises for a device failure."""
    from omnisort_hw.cell.devices import open_arm, open_camera, open_laser
    from omnisort_hw.config.cell import load_cell_config

    cell = load_cell_config(config_path).devices
    openers = {"camera": open_camera, "laser": open_laser, "arm": open_arm}
    rows: list[CheckRow] = []
    for kind, section in cell.sections():
        if only and kind not in only:
            continue
        if section is None:
            rows.append(CheckRow(kind, "-", "-", True, "not configured", "", 0.0))
            continue
        t0 = time.monotonic()
        try:
            device = openers[kind](section, cell.base_dir)
            with device:
                detail = _exercise(device)
            ok, status = True, "ok"
        except Exception as exc:
            code = getattr(exc, "code", None)
            if not isinstance(code, str):
                raise
            ok, status, detail = False, code, str(exc)
        rows.append(
            CheckRow(
                kind, section.backend, _where(section), ok, status, detail, time.monotonic() - t0
            )
        )
    return rows


def format_table(rows: list[CheckRow]) -> str:
    header = ("DEVICE", "BACKEND", "WHERE", "STATUS", "TIME", "DETAIL")
    body = [(r.device, r.backend, r.where, r.status, f"{r.seconds:.2f}s", r.detail) for r in rows]
    widths = [max(len(str(line[i])) for line in [header, *body]) for i in range(5)]
    lines = []
    for line in [header, *body]:
        cells = [str(line[i]).ljust(widths[i]) for i in range(5)]
        lines.append("  ".join([*cells, str(line[5])]).rstrip())
    return "\n".join(lines)


def run_check(args: argparse.Namespace) -> int:
    rows = check_devices(args.config, args.only)
    if args.json:
        print_result({"devices": [asdict(r) for r in rows]}, indent=2)
    else:
        print(format_table(rows))
    return 0 if all(r.ok for r in rows) else EXIT_DEVICE_FAILED


def run_laser(args: argparse.Namespace) -> int:
    from omnisort_hw.cell.devices import open_laser
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.errors import ConfigError

    cell = load_cell_config(args.config).devices
    if cell.laser is None:
        raise ConfigError(f"{args.config}: no [laser] section")
    with open_laser(cell.laser, cell.base_dir) as laser:
        if args.action != "state":
            laser.set(args.action == "on")
        state = laser.state()
    print(f"laser {'ON' if state else 'OFF'} ({laser.name})")
    return 0
