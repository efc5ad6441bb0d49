"""Discovery of cameras (/dev/video* + sysfs + V4L2 ioctls) and serial ports."""

from __future__ import annotations

from pathlib import Path

from drivers.discovery import CameraInfo, SerialPortInfo, list_cameras, list_serial_ports


def test_cameras_are_listed_in_numeric_order_with_their_sysfs_names(tmp_path: Path) -> None:
    dev, sysfs = tmp_path / "dev", tmp_path / "sys"
    for n, name in ((10, "Fisheye USB"), (2, "Integrated Camera")):
        (dev).mkdir(exist_ok=True)
        (dev / f"video{n}").write_bytes(b"")
        (sysfs / f"video{n}").mkdir(parents=True)
        (sysfs / f"video{n}" / "name").write_text(name + "\n")
    (dev / "videofoo").write_bytes(b"")  # not a video node name
    cams = list_cameras(dev, sysfs)
    assert [c.index for c in cams] == [2, 10]
    assert [c.name for c in cams] == ["Integrated Camera", "Fisheye USB"]
    # Plain files are no V4L2 devices: the ioctl fails and says so instead of raising.
    assert all("not a V4L2 device" in c.error for c in cams)
    assert "Fisheye USB" in cams[1].describe()


def test_camera_description_lists_formats_and_sizes() -> None:
    info = CameraInfo(
        "/dev/video0", 0, "Fisheye", formats={"MJPG": [(1920, 1080), (640, 480)], "YUYV": []}
    )
    text = info.describe()
    assert "MJPG (1920x1080 640x480)" in text and "YUYV" in text and "capture" in text


def test_no_cameras_is_an_empty_list(tmp_path: Path) -> None:
    assert list_cameras(tmp_path, tmp_path) == []


def test_serial_ports_are_listed() -> None:
    ports = list_serial_ports()
    assert all(isinstance(p, SerialPortInfo) and p.device.startswith("/dev/") for p in ports)
    assert [p.device for p in ports] == sorted(p.device for p in ports)
