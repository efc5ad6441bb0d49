"""The V4L2 camera class run on OpenCV's file and image-sequence sources (no camera here).

Covers frames, sequence numbers and timestamps, a source that ends or is truncated mid-stream
(DeviceDisconnectedError, then bounded reconnect with back-off in the log), a source that
stalls (DeviceTimeoutError within the read timeout: one image of the sequence is a FIFO that
blocks the reader), a missing source and a swapped one.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers.errors import (
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    UnsupportedError,
)
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig
from tests.drivers.contract import CameraContract

pytestmark = pytest.mark.timeout(20)

W, H = 64, 48


def frame_image(i: int) -> np.ndarray:
    """A frame whose value encodes its index (robust to MJPG compression)."""
    img = np.full((H, W, 3), (i * 30) % 250, np.uint8)
    img[:, : W // 2, 2] = 200
    return img


def write_sequence(folder: Path, n: int) -> str:
    for i in range(n):
        cv2.imwrite(str(folder / f"img_{i:03d}.png"), frame_image(i))
    return str(folder / "img_%03d.png")


def write_video(path: Path, n: int) -> str:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (W, H))
    assert writer.isOpened()
    for i in range(n):
        writer.write(frame_image(i))
    writer.release()
    return str(path)


def camera(device: str, api: str, **overrides: object) -> V4L2Camera:
    settings: dict[str, object] = {
        "device": device,
        "api": api,
        "read_timeout_s": 1.0,
        "reconnect_backoff_s": 0.05,
        "reconnect_backoff_max_s": 0.2,
        "reconnect_attempts": 3,
    }
    settings.update(overrides)
    return V4L2Camera(V4L2CameraConfig(**settings))  # type: ignore[arg-type]


def level(frame_img: np.ndarray) -> int:
    return round(float(frame_img[:, W // 2 :, 0].mean()) / 30)


class TestImageSequenceContract(CameraContract):
    @pytest.fixture
    def make_camera(self, tmp_path: Path) -> Callable[[], V4L2Camera]:
        pattern = write_sequence(tmp_path, 6)
        return lambda: camera(pattern, "images")


class TestVideoFileContract(CameraContract):
    @pytest.fixture
    def make_camera(self, tmp_path: Path) -> Callable[[], V4L2Camera]:
        path = write_video(tmp_path / "clip.avi", 6)
        return lambda: camera(path, "ffmpeg")


def test_frames_come_in_order_with_sequence_numbers(tmp_path: Path) -> None:
    with camera(write_video(tmp_path / "clip.avi", 5), "ffmpeg") as cam:
        assert cam.resolution == (W, H)
        frames = [cam.grab() for _ in range(5)]
    assert [f.sequence for f in frames] == [0, 1, 2, 3, 4]
    assert [level(f.image) for f in frames] == [0, 1, 2, 3, 4]


def test_sequence_that_ends_is_a_disconnection_then_a_logged_reconnect(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="drivers.camera")
    with camera(write_sequence(tmp_path, 3), "images") as cam:
        assert [cam.grab().sequence for _ in range(3)] == [0, 1, 2]
        t0 = time.monotonic()
        with pytest.raises(DeviceDisconnectedError, match="stopped delivering frames"):
            cam.grab()
        assert time.monotonic() - t0 < 1.0
        assert not cam.is_connected
        frame = cam.grab()  # reopens the source
        assert frame.sequence == 3 and level(frame.image) == 0
        assert cam.is_connected
    messages = [r.getMessage() for r in caplog.records]
    assert any("lost: grab failed" in m for m in messages)
    assert any("reconnect attempt 1/3" in m for m in messages)
    assert any("reconnected after 1 attempt" in m for m in messages)


def test_truncated_video_file_is_a_disconnection(tmp_path: Path) -> None:
    path = Path(write_video(tmp_path / "clip.avi", 40))
    with camera(str(path), "ffmpeg") as cam:
        cam.grab()
        with path.open("r+b") as f:
            f.truncate(path.stat().st_size // 3)
        with pytest.raises(DeviceDisconnectedError):
            for _ in range(40):
                cam.grab()


def test_reconnect_backs_off_and_gives_up_after_the_attempt_limit(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="drivers.camera")
    path = Path(write_video(tmp_path / "clip.avi", 2))
    cam = camera(str(path), "ffmpeg")
    cam.connect()
    cam.grab()
    cam.grab()
    with pytest.raises(DeviceDisconnectedError):
        cam.grab()
    path.unlink()  # the camera is really gone now
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnectedError, match="gave up after 3 reconnect attempts"):
        cam.grab(timeout_s=5.0)
    elapsed = time.monotonic() - t0
    # back-off 0.05 s then 0.1 s between the three attempts
    assert 0.15 * 0.9 <= elapsed < 1.5
    failures = [
        r
        for r in caplog.records
        if "reconnect attempt" in r.getMessage() and "failed" in r.getMessage()
    ]
    assert len(failures) == 3
    with pytest.raises(DeviceDisconnectedError, match="gave up"):
        cam.grab()
    cam.close()


def test_grab_during_back_off_does_not_wait_past_its_timeout(tmp_path: Path) -> None:
    path = Path(write_video(tmp_path / "clip.avi", 1))
    cam = camera(str(path), "ffmpeg", reconnect_backoff_s=5.0, reconnect_backoff_max_s=5.0)
    cam.connect()
    cam.grab()
    with pytest.raises(DeviceDisconnectedError):
        cam.grab()
    path.unlink()
    with pytest.raises(DeviceDisconnectedError):
        cam.grab(timeout_s=0.5)  # first attempt fails, next one is 5 s away
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnectedError, match="next reconnect attempt in"):
        cam.grab(timeout_s=0.5)
    assert time.monotonic() - t0 < 0.2
    cam.close()


def _unblock_fifo(path: Path, worker_alive: Callable[[], bool]) -> None:
    """Feed the FIFO until the reader stuck on it has returned."""
    data = cv2.imencode(".png", frame_image(9))[1].tobytes()
    end = time.monotonic() + 5.0
    while worker_alive() and time.monotonic() < end:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:
            time.sleep(0.01)
            continue
        try:
            os.write(fd, data)
        except OSError:
            pass
        finally:
            os.close(fd)
        time.sleep(0.01)


def test_stalled_source_times_out_within_the_read_timeout(tmp_path: Path) -> None:
    pattern = write_sequence(tmp_path, 4)
    cam = camera(pattern, "images", read_timeout_s=0.3)
    cam.connect()
    cam.grab()
    stalled = tmp_path / "img_001.png"
    stalled.unlink()
    os.mkfifo(stalled)  # reading frame 1 now blocks, like a camera that stops sending
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeoutError, match=r"no frame within 0\.30 s"):
        cam.grab()
    assert 0.3 <= time.monotonic() - t0 < 0.8
    hung = cam._hung
    assert hung is not None
    threading.Thread(target=_unblock_fifo, args=(stalled, hung.is_alive), daemon=True).start()
    hung.join(5.0)
    assert not hung.is_alive()
    cam.close()


def test_missing_sources_are_device_not_found(tmp_path: Path) -> None:
    with pytest.raises(DeviceNotFoundError, match="does not exist"):
        camera(str(tmp_path / "none.avi"), "ffmpeg").connect()
    with pytest.raises(DeviceNotFoundError, match="no images match"):
        camera(str(tmp_path / "none_%03d.png"), "images").connect()
    with pytest.raises(DeviceNotFoundError, match="/dev/video99"):
        camera("/dev/video99", "v4l2").connect()


def test_unreadable_file_is_device_not_found(tmp_path: Path) -> None:
    bogus = tmp_path / "not_a_video.avi"
    bogus.write_bytes(b"this is not a video" * 100)
    with pytest.raises(DeviceNotFoundError, match="cannot read"):
        camera(str(bogus), "ffmpeg").connect()


def test_a_different_camera_is_refused(tmp_path: Path) -> None:
    path = write_video(tmp_path / "clip.avi", 3)
    with pytest.raises(DeviceConfigError, match="different camera") as info:
        camera(path, "ffmpeg", expected_serial="usb-046d:0825-ABC").connect()
    assert info.value.key == "[camera].expected_serial"


def test_file_sources_have_no_manual_exposure(tmp_path: Path) -> None:
    with camera(write_video(tmp_path / "clip.avi", 3), "ffmpeg") as cam:
        with pytest.raises(UnsupportedError, match="manual exposure"):
            cam.set_exposure_ms(1.0)
        with pytest.raises(UnsupportedError):
            cam.exposure_ms = 1.0


@pytest.mark.parametrize(
    ("settings", "key"),
    [
        ({"pixel_format": "H264"}, "pixel_format"),
        ({"api": "dshow"}, "api"),
        ({"fps": 0}, "fps"),
        ({"buffer_size": 0}, "buffer_size"),
        ({"read_timeout_s": 0}, "read_timeout_s"),
        ({"reconnect_backoff_s": 1.0, "reconnect_backoff_max_s": 0.5}, "reconnect_backoff_max_s"),
    ],
)
def test_bad_settings_name_the_key(settings: dict[str, object], key: str) -> None:
    with pytest.raises(DeviceConfigError) as info:
        V4L2CameraConfig(**settings)  # type: ignore[arg-type]
    assert info.value.key == f"[camera].{key}"
