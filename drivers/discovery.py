"""What is attached: V4L2 cameras and serial ports.

Cameras are found from `/dev/video*` and `/sys/class/video4linux/*/name`; their pixel formats and
frame sizes are asked from the kernel with the V4L2 ioctls `VIDIOC_QUERYCAP`, `VIDIOC_ENUM_FMT`
and `VIDIOC_ENUM_FRAMESIZES` (OpenCV cannot enumerate them; it only reports the current one).
Metadata-only nodes (the second `/dev/videoN` a UVC camera creates) are flagged so the user
picks the capture node. Nothing here opens a stream, so it is safe while a camera is in use.
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

# ioctl numbers: _IOR/_IOWR('V', nr, size) from <linux/videodev2.h>.
_VIDIOC_QUERYCAP = 0x80685600  # _IOR('V', 0, struct v4l2_capability[104])
_VIDIOC_ENUM_FMT = 0xC0405602  # _IOWR('V', 2, struct v4l2_fmtdesc[64])
_VIDIOC_ENUM_FRAMESIZES = 0xC02C564A  # _IOWR('V', 74, struct v4l2_frmsizeenum[44])
_BUF_TYPE_VIDEO_CAPTURE = 1
_CAP_VIDEO_CAPTURE = 0x00000001
_CAP_DEVICE_CAPS = 0x80000000
_FRMSIZE_TYPE_DISCRETE = 1


@dataclass(frozen=True)
class CameraInfo:
    """One `/dev/videoN` node."""

    path: str
    index: int
    name: str
    driver: str = ""
    bus: str = ""
    is_capture: bool = True
    formats: dict[str, list[tuple[int, int]]] = field(default_factory=dict)
    error: str = ""

    def describe(self) -> str:
        """One line for `omnisort devices list`."""
        kind = "capture" if self.is_capture else "metadata/other (not a capture node)"
        fmts = (
            ", ".join(f"{fourcc} {_sizes_text(sizes)}" for fourcc, sizes in self.formats.items())
            or "formats unknown"
        )
        text = f"{self.path}  {self.name!r}  {kind}  [{fmts}]"
        if self.bus:
            text += f"  bus {self.bus}"
        if self.error:
            text += f"  ({self.error})"
        return text


@dataclass(frozen=True)
class SerialPortInfo:
    """One serial port as pyserial lists it."""

    device: str
    description: str
    hwid: str
    serial_number: str | None = None
    vid: int | None = None
    pid: int | None = None

    def describe(self) -> str:
        """One line for `omnisort devices list`."""
        ident = f" {self.vid:04x}:{self.pid:04x}" if self.vid is not None and self.pid else ""
        sn = f" serial {self.serial_number}" if self.serial_number else ""
        return f"{self.device}  {self.description}{ident}{sn}"


def _sizes_text(sizes: list[tuple[int, int]]) -> str:
    if not sizes:
        return ""
    shown = sorted(set(sizes), key=lambda s: s[0] * s[1], reverse=True)
    return (
        "(" + " ".join(f"{w}x{h}" for w, h in shown[:4]) + (" ..." if len(shown) > 4 else "") + ")"
    )


def _cstr(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace")


def _fourcc_text(code: int) -> str:
    return "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4)).strip()


def _query_v4l2(fd: int) -> tuple[str, str, bool, dict[str, list[tuple[int, int]]]]:
    """(driver, bus, is_capture, {fourcc: [(w, h), ...]}) of an open V4L2 node."""
    cap = bytearray(104)
    fcntl.ioctl(fd, _VIDIOC_QUERYCAP, cap)
    driver, bus = _cstr(bytes(cap[0:16])), _cstr(bytes(cap[48:80]))
    capabilities, device_caps = struct.unpack_from("<II", cap, 84)
    caps = device_caps if capabilities & _CAP_DEVICE_CAPS else capabilities
    is_capture = bool(caps & _CAP_VIDEO_CAPTURE)
    formats: dict[str, list[tuple[int, int]]] = {}
    if not is_capture:
        return driver, bus, is_capture, formats
    for fmt_index in range(64):
        desc = bytearray(struct.pack("<II", fmt_index, _BUF_TYPE_VIDEO_CAPTURE) + bytes(56))
        try:
            fcntl.ioctl(fd, _VIDIOC_ENUM_FMT, desc)
        except OSError:
            break
        pixfmt = struct.unpack_from("<I", desc, 44)[0]
        sizes: list[tuple[int, int]] = []
        for size_index in range(256):
            fs = bytearray(struct.pack("<II", size_index, pixfmt) + bytes(36))
            try:
                fcntl.ioctl(fd, _VIDIOC_ENUM_FRAMESIZES, fs)
            except OSError:
                break
            ftype, w, h = struct.unpack_from("<III", fs, 8)
            if ftype != _FRMSIZE_TYPE_DISCRETE:
                # Stepwise/continuous: report the largest size only.
                sizes.append(
                    (struct.unpack_from("<I", fs, 16)[0], struct.unpack_from("<I", fs, 28)[0])
                )
                break
            sizes.append((w, h))
        formats[_fourcc_text(pixfmt)] = sizes
    return driver, bus, is_capture, formats


def node_formats(node: str | Path) -> tuple[str, ...]:
    """The FOURCCs a V4L2 node offers (VIDIOC_ENUM_FMT), empty when it cannot be queried."""
    try:
        fd = os.open(node, os.O_RDWR | os.O_NONBLOCK)
    except OSError:
        return ()
    try:
        return tuple(_query_v4l2(fd)[3])
    except OSError:
        return ()
    finally:
        os.close(fd)


def list_cameras(
    dev_dir: str | Path = "/dev", sys_dir: str | Path = "/sys/class/video4linux"
) -> list[CameraInfo]:
    """Every `/dev/videoN` with its name (from sysfs), capture capability and formats."""
    dev, sysfs = Path(dev_dir), Path(sys_dir)
    out: list[CameraInfo] = []
    nodes = sorted(
        (p for p in dev.glob("video*") if re.fullmatch(r"video\d+", p.name)),
        key=lambda p: int(p.name[5:]),
    )
    for node in nodes:
        index = int(node.name[5:])
        try:
            name = (sysfs / node.name / "name").read_text().strip()
        except OSError:
            name = "?"
        formats: dict[str, list[tuple[int, int]]]
        driver, bus, is_capture, formats, error = "", "", True, {}, ""
        try:
            fd = os.open(node, os.O_RDWR | os.O_NONBLOCK)
        except OSError as exc:
            error = (
                "no permission: add the user to group 'video'"
                if exc.errno in (errno.EACCES, errno.EPERM)
                else f"cannot open: {exc.strerror}"
            )
        else:
            try:
                driver, bus, is_capture, formats = _query_v4l2(fd)
            except OSError as exc:
                error = f"not a V4L2 device: {exc.strerror}"
            finally:
                os.close(fd)
        out.append(CameraInfo(str(node), index, name, driver, bus, is_capture, formats, error))
    return out


def list_serial_ports() -> list[SerialPortInfo]:
    """Serial ports from pyserial's `list_ports` (USB adapters, on-board UARTs)."""
    from serial.tools import list_ports

    return [
        SerialPortInfo(
            device=p.device,
            description=p.description or "",
            hwid=p.hwid or "",
            serial_number=p.serial_number,
            vid=p.vid,
            pid=p.pid,
        )
        for p in sorted(list_ports.comports(), key=lambda p: p.device)
    ]


__all__ = ["CameraInfo", "SerialPortInfo", "list_cameras", "list_serial_ports"]
