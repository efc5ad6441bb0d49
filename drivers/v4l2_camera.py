"""Camera through OpenCV's VideoCapture: V4L2 devices on the cell PC, files for tests.

`api = "v4l2"` opens `/dev/videoN` (or an index, or a `/dev/v4l/by-id/...` link) with OpenCV's
V4L2 backend, sets the pixel format (MJPG or YUYV), size and frame rate, and manual exposure
and gain when configured. `api = "ffmpeg"` (a video file) and `api = "images"` (a sequence such
as `img_%03d.png`) run the same class on recorded data, which is how it is tested here.

Fresh frames (V4L2): the driver asks for one kernel buffer (`CAP_PROP_BUFFERSIZE = 1`; the
driver may keep a few more) and then grabs and discards frames until one carries a kernel
timestamp (`CAP_PROP_POS_MSEC`, CLOCK_MONOTONIC for UVC) later than the moment `grab()` was
called plus the exposure time, i.e. a frame whose exposure began after the call. When the
timestamps are not on the monotonic clock it counts instead of timing: it discards as many
frames as the kernel can hold (`buffer_size`, or the larger count the driver reports), plus one
per frame period of exposure, so the frame it keeps was taken into a buffer queued after the
call; a dequeue's duration proves nothing on a loaded machine. After an exposure or gain
change the next `settle_frames` frames are discarded too. File sources return the next frame.
Streams carry no capture time: a reader thread keeps reading and stamps each frame on arrival,
and `grab()` returns the first frame that arrived one frame period after the call.

Timeouts: every OpenCV call that can block (open, grab) runs in a helper thread that is waited
for at most `open_timeout_s` / `read_timeout_s`; a camera that stops delivering frames raises
`DeviceTimeoutError` instead of hanging. When the source fails (unplugged, file ended), that
`grab()` raises `DeviceDisconnectedError`; later calls reopen it with exponential back-off
(logged), re-apply exposure and gain, and refuse a different camera (serial changed).

Over 600 lines: one device and its recorded stand-ins behind one class (opening, formats,
controls, fresh frames, serial numbers); the fresh-frame rule needs all of them.
"""

from __future__ import annotations

import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal, TypeVar

import cv2
import numpy as np

from drivers._common import Backoff, StillRunningError, call_with_timeout, require
from drivers.base import DEFAULT_GRAB_TIMEOUT_S, Camera, Frame
from drivers.errors import (
    DeviceBusyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    UnsupportedError,
)
from drivers.stream_source import StreamReader, is_stream_url, probe_stream, stream_serial
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import InputError

log = logging.getLogger("drivers.camera")
T = TypeVar("T")

_APIS = {
    "v4l2": cv2.CAP_V4L2,
    "ffmpeg": cv2.CAP_FFMPEG,
    "images": cv2.CAP_IMAGES,
    "any": cv2.CAP_ANY,
    "stream": cv2.CAP_FFMPEG,
}
_V4L2_EXPOSURE_MANUAL = 1  # V4L2_EXPOSURE_MANUAL, passed through by OpenCV's V4L2 backend
_V4L2_EXPOSURE_UNIT_MS = 0.1  # V4L2_CID_EXPOSURE_ABSOLUTE counts 100 µs


@dataclass(frozen=True)
class V4L2CameraConfig:
    """Settings of `[camera]` with `backend = "v4l2"`.

    `exposure_ms = 0` and `gain < 0` leave the camera's automatic settings alone.
    `reconnect_attempts = 0` retries forever (with the back-off capped at
    `reconnect_backoff_max_s`). `expected_serial` (see `omnisort devices list`) refuses a
    different camera at the same path.
    """

    SECTION: ClassVar[str] = "camera"

    device: str = "/dev/video0"
    api: Literal["v4l2", "ffmpeg", "images", "any", "stream"] = "v4l2"
    pixel_format: Literal["MJPG", "YUYV"] = "MJPG"
    width: int = 1920
    height: int = 1080
    fps: float = 30.0
    exposure_ms: float = 0.0
    gain: float = -1.0
    buffer_size: int = 1
    settle_frames: int = 2
    read_timeout_s: float = DEFAULT_GRAB_TIMEOUT_S
    open_timeout_s: float = 5.0
    reconnect_attempts: int = 5
    reconnect_backoff_s: float = 0.5
    reconnect_backoff_max_s: float = 8.0
    expected_serial: str = ""
    tone_curve: str = "srgb"

    def __post_init__(self) -> None:
        s = self.SECTION
        try:
            ToneCurve.parse(self.tone_curve)
        except InputError as exc:
            require(False, s, "tone_curve", str(exc))
        require(bool(str(self.device)), s, "device", "give /dev/videoN, an index or a file")
        require(self.api in _APIS, s, "api", f"must be one of {sorted(_APIS)}")
        require(
            (self.api == "stream") == is_stream_url(str(self.device)),
            s,
            "device",
            'api = "stream" takes an http://, https:// or rtsp:// URL (and only it does)',
        )
        require(self.pixel_format in ("MJPG", "YUYV"), s, "pixel_format", "MJPG or YUYV")
        require(self.width > 0 and self.height > 0, s, "width", "width and height must be > 0")
        require(self.fps > 0, s, "fps", f"must be > 0, got {self.fps}")
        require(self.exposure_ms >= 0, s, "exposure_ms", "must be >= 0 (0 = automatic)")
        require(1 <= self.buffer_size <= 8, s, "buffer_size", "must be 1..8")
        require(0 <= self.settle_frames <= 10, s, "settle_frames", "must be 0..10")
        require(self.read_timeout_s > 0, s, "read_timeout_s", "must be > 0")
        require(self.open_timeout_s > 0, s, "open_timeout_s", "must be > 0")
        require(self.reconnect_attempts >= 0, s, "reconnect_attempts", "must be >= 0")
        require(self.reconnect_backoff_s > 0, s, "reconnect_backoff_s", "must be > 0")
        require(
            self.reconnect_backoff_max_s >= self.reconnect_backoff_s,
            s,
            "reconnect_backoff_max_s",
            "must be >= reconnect_backoff_s",
        )


def _resolve_v4l2(device: str) -> str | int:
    """`"0"` -> 0, a by-id link -> `/dev/videoN`, anything else unchanged."""
    if device.isdigit():
        return int(device)
    return os.path.realpath(device) if device.startswith("/dev/") else device


def v4l2_serial(node: str | int) -> str:
    """A stable identifier from sysfs: USB vendor:product plus serial number or bus port."""
    name = f"video{node}" if isinstance(node, int) else Path(str(node)).name
    sys_dev = Path("/sys/class/video4linux") / name / "device"
    try:
        usb = sys_dev.resolve().parent
        vid = (usb / "idVendor").read_text().strip()
        pid = (usb / "idProduct").read_text().strip()
        sn_path = usb / "serial"
        sn = sn_path.read_text().strip() if sn_path.exists() else f"port-{usb.name}"
        return f"usb-{vid}:{pid}-{sn}"
    except OSError:
        pass
    try:
        return "v4l2-" + (Path("/sys/class/video4linux") / name / "name").read_text().strip()
    except OSError:
        return f"v4l2-{name}"


class V4L2Camera(Camera):
    """A camera read through `cv2.VideoCapture`; see the module docstring for the guarantees."""

    def __init__(self, config: V4L2CameraConfig) -> None:
        self.config = config
        self._cap: Any = None
        self._reader: StreamReader | None = None
        self._lock = threading.RLock()
        self._hung: threading.Thread | None = None
        self._lost = False
        self._sequence = 0
        self._serial = ""
        self._resolution = (0, 0)
        self._exposure_ms = config.exposure_ms
        self._gain = config.gain
        self._pixel_format: str = config.pixel_format
        self._discard = 0
        self._backoff = Backoff(
            config.reconnect_backoff_s, config.reconnect_backoff_max_s, config.reconnect_attempts
        )

    @property
    def name(self) -> str:
        return f"camera {self.config.device} ({self.config.api})"

    @property
    def is_connected(self) -> bool:
        return self._cap is not None

    @property
    def resolution(self) -> tuple[int, int]:
        return self._resolution

    @property
    def serial(self) -> str:
        return self._serial

    @property
    def tone_curve(self) -> str:
        return self.config.tone_curve

    @property
    def pixel_formats(self) -> tuple[str, ...]:
        """What the V4L2 node offers (VIDIOC_ENUM_FMT); files and streams cannot tell."""
        if self.config.api != "v4l2":
            return ()
        from drivers.discovery import node_formats

        node = _resolve_v4l2(self.config.device)
        return node_formats(f"/dev/video{node}" if isinstance(node, int) else node)

    @property
    def pixel_format(self) -> str:
        """The configured FOURCC on a V4L2 device; "" for files and streams (they deliver
        whatever they were written with)."""
        return self._pixel_format if self.config.api == "v4l2" else ""

    def set_pixel_format(self, fourcc: str) -> None:
        """Switch a V4L2 device's pixel format (OpenCV's CAP_PROP_FOURCC restarts the stream);
        the delivered format is read back. Files and streams raise `UnsupportedError`."""
        if self.config.api != "v4l2":
            raise UnsupportedError(
                f"{self.name}: a {self.config.api} source delivers the format it holds; it "
                f"cannot switch to {fourcc}",
                device=self.config.device,
            )
        with self._lock:
            cap = self._connected_cap()
            if fourcc == self._pixel_format:
                return
            cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*fourcc))
            code = int(cap.get(cv2.CAP_PROP_FOURCC))
            got = "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4))
            if got != fourcc:
                raise UnsupportedError(
                    f"{self.name} does not deliver {fourcc} (it gives {got!r})",
                    device=self.config.device,
                )
            self._pixel_format = fourcc
            self._discard = self.config.settle_frames

    @property
    def sequence(self) -> int:
        """Number of frames returned so far (the next frame gets this number)."""
        return self._sequence

    def _blocking(self, fn: Callable[[], T], timeout_s: float, what: str) -> T:
        """Run a possibly blocking OpenCV call in a helper thread, waiting at most `timeout_s`."""
        if self._hung is not None:
            self._hung.join(timeout_s)
            if self._hung.is_alive():
                raise DeviceTimeoutError(
                    f"{self.name} is still stuck in an earlier call: unplug and replug it, or "
                    "restart the service",
                    device=self.config.device,
                )
            self._hung = None
        try:
            return call_with_timeout(fn, timeout_s, f"camera-{what}")
        except StillRunningError as stuck:
            self._hung = stuck.worker
            raise DeviceTimeoutError(
                f"{self.name}: no {what} within {timeout_s:.2f} s (camera stalled? check the "
                "cable, USB bandwidth, or a too long [camera].exposure_ms)",
                device=self.config.device,
            ) from None

    def _check_source_exists(self) -> None:
        cfg = self.config
        target = str(cfg.device)
        if cfg.api == "stream":
            probe_stream(target, cfg.open_timeout_s)
        elif cfg.api == "images":
            first = _first_sequence_file(target)
            if first is None:
                raise DeviceNotFoundError(
                    f"no images match the sequence {target}: check [camera].device",
                    device=target,
                )
        elif (cfg.api in ("ffmpeg", "any") or target.startswith("/dev/")) and not os.path.exists(
            target
        ):
            hint = "is the camera plugged in? (`omnisort devices list`)"
            raise DeviceNotFoundError(f"{target} does not exist: {hint}", device=target)

    def _open(self) -> None:
        """Open the source and apply format, size, rate, exposure and gain. Raises typed errors."""
        cfg = self.config
        self._check_source_exists()
        source: str | int = _resolve_v4l2(cfg.device) if cfg.api == "v4l2" else cfg.device
        api = _APIS[cfg.api]

        def do_open() -> Any:
            if cfg.api == "stream":
                ms = [
                    cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
                    int(cfg.open_timeout_s * 1000),
                    cv2.CAP_PROP_READ_TIMEOUT_MSEC,  # grab() has its own timeout; a still
                    3_600_000,  # stream (the server sends nothing while the arm moves) is fine
                ]
                return cv2.VideoCapture(source, api, ms)
            return cv2.VideoCapture(source, api)

        cap = self._blocking(do_open, cfg.open_timeout_s, "open")
        if not cap.isOpened():
            cap.release()
            if cfg.api == "v4l2":
                raise DeviceBusyError(
                    f"{self.name} exists but cannot be opened: another program may be using it "
                    f"(`fuser {source}`), or it is a metadata node (pick the capture node shown "
                    "by `omnisort devices list`)",
                    device=cfg.device,
                )
            raise DeviceNotFoundError(
                f"OpenCV cannot read {cfg.device} with api {cfg.api!r}: check [camera].device "
                "and [camera].api",
                device=cfg.device,
            )
        try:
            if cfg.api == "v4l2":
                self._configure_v4l2(cap)
                serial = v4l2_serial(source)
            elif cfg.api == "stream":
                serial = stream_serial(cfg.device)
            else:
                serial = f"file:{os.path.abspath(cfg.device)}"
        except DeviceError:
            cap.release()
            raise
        expected = cfg.expected_serial or self._serial
        if expected and serial != expected:
            cap.release()
            key = "[camera].expected_serial"
            raise DeviceConfigError(
                f"a different camera is at {cfg.device}: serial {serial!r}, expected "
                f"{expected!r}; recalibrate the intrinsics for the new camera or update {key}",
                key=key,
                device=cfg.device,
            )
        self._serial = serial
        width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self._resolution = (width, height)
        self._cap = cap
        if cfg.api == "stream":
            self._reader = StreamReader(cap, cfg.device)
        self._lost = False
        self._backoff.reset()

    def _configure_v4l2(self, cap: Any) -> None:
        cfg = self.config
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter.fourcc(*self._pixel_format))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, cfg.width)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, cfg.height)
        cap.set(cv2.CAP_PROP_FPS, cfg.fps)
        cap.set(cv2.CAP_PROP_BUFFERSIZE, cfg.buffer_size)
        fourcc = int(cap.get(cv2.CAP_PROP_FOURCC))
        got = "".join(chr((fourcc >> (8 * i)) & 0xFF) for i in range(4))
        if got != self._pixel_format:
            raise DeviceConfigError(
                f"{self.name} does not deliver {self._pixel_format} (it gives {got!r}); pick a "
                "format shown by `omnisort devices list` for [camera].pixel_format",
                key="[camera].pixel_format",
                device=cfg.device,
            )
        size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        if size != (cfg.width, cfg.height):
            raise DeviceConfigError(
                f"{self.name} cannot do {cfg.width}x{cfg.height} in {cfg.pixel_format} (it "
                f"gives {size[0]}x{size[1]}); pick a size shown by `omnisort devices list` for "
                "[camera].width/height",
                key="[camera].width",
                device=cfg.device,
            )
        fps = cap.get(cv2.CAP_PROP_FPS)
        if fps and abs(fps - cfg.fps) > 0.5:
            log.warning(
                "%s runs at %.1f fps instead of [camera].fps = %.1f", self.name, fps, cfg.fps
            )
        if self._exposure_ms > 0:
            self._apply_exposure(cap, self._exposure_ms)
        if self._gain >= 0:
            self._apply_gain(cap, self._gain)

    def connect(self) -> None:
        """Open the camera; a second call while connected does nothing."""
        with self._lock:
            if self._cap is not None:
                return
            self._sequence = 0
            self._open()
            self._discard = self.config.settle_frames if self.config.api == "v4l2" else 0
            log.info("%s connected: %dx%d, serial %s", self.name, *self._resolution, self._serial)

    def close(self) -> None:
        with self._lock:
            self._release()
            self._lost = False
            self._backoff.reset()

    def _release(self) -> None:
        cap, self._cap = self._cap, None
        reader, self._reader = self._reader, None
        if reader is not None:
            reader.stop()  # its thread releases the capture
        elif cap is not None and (self._hung is None or not self._hung.is_alive()):
            cap.release()

    def _mark_lost(self, why: str) -> DeviceDisconnectedError:
        self._release()
        self._lost = True
        self._backoff.next_time = 0.0
        log.warning("%s lost: %s; will reconnect with back-off on the next grab", self.name, why)
        return DeviceDisconnectedError(
            f"{self.name} stopped delivering frames ({why}): check the cable; the driver "
            "reconnects on the next grab",
            device=self.config.device,
        )

    def _reconnect(self, deadline: float) -> None:
        """Reopen a lost source, respecting the back-off schedule, until `deadline`."""
        cfg = self.config
        while True:
            if self._backoff.exhausted():
                raise DeviceDisconnectedError(
                    f"{self.name} is gone: gave up after {self._backoff.count} reconnect "
                    "attempts; check the cable, then reconnect (restart or `connect()`)",
                    device=cfg.device,
                )
            wait = self._backoff.wait_s()
            if time.monotonic() + wait >= deadline:
                raise DeviceDisconnectedError(
                    f"{self.name} is gone; next reconnect attempt in {wait:.1f} s "
                    f"({self._backoff.count} failed so far)",
                    device=cfg.device,
                )
            time.sleep(wait)
            attempt = self._backoff.count + 1
            limit = cfg.reconnect_attempts or "unlimited"
            log.warning("%s: reconnect attempt %d/%s", self.name, attempt, limit)
            try:
                self._open()
            except DeviceConfigError:
                raise
            except DeviceError as exc:
                delay = self._backoff.failed()
                log.warning(
                    "%s: reconnect attempt %d failed (%s); next in %.1f s",
                    self.name,
                    attempt,
                    exc,
                    delay,
                )
                continue
            self._discard = cfg.settle_frames if cfg.api == "v4l2" else 0
            log.warning("%s reconnected after %d attempt(s)", self.name, attempt)
            return

    def grab(self, timeout_s: float | None = None) -> Frame:
        """A frame captured after this call started; see the module docstring."""
        cfg = self.config
        timeout = cfg.read_timeout_s if timeout_s is None else timeout_s
        with self._lock:
            t_call = time.monotonic()
            deadline = t_call + timeout
            if self._cap is None:
                if not self._lost:
                    raise DeviceDisconnectedError(
                        f"{self.name} is not connected: call connect() first", device=cfg.device
                    )
                self._reconnect(deadline)
            if cfg.api == "v4l2":
                image, stamp = self._grab_fresh(t_call, deadline)
            elif cfg.api == "stream":
                image, stamp = self._grab_stream(t_call, deadline)
            else:
                image, stamp = self._read_one(deadline)
            frame = Frame(
                image=image,
                timestamp=stamp,
                wall_time=time.time() - (time.monotonic() - stamp),
                sequence=self._sequence,
            )
            self._sequence += 1
            return frame

    def _grab_once(self, deadline: float) -> None:
        """`cap.grab()` within the deadline."""
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise DeviceTimeoutError(
                f"{self.name}: no fresh frame within the timeout", device=self.config.device
            )
        ok = self._blocking(self._cap.grab, remaining, "frame")
        if not ok:
            raise self._mark_lost("grab failed")

    def _retrieve(self) -> np.ndarray:
        ok, image = self._cap.retrieve()
        if not ok or image is None:
            raise self._mark_lost("frame could not be decoded")
        return _to_bgr(image)

    def _read_one(self, deadline: float) -> tuple[np.ndarray, float]:
        try:
            self._grab_once(deadline)
        except DeviceTimeoutError:
            self._release()
            self._lost = True
            raise
        stamp = time.monotonic()
        image = self._retrieve()
        if self._resolution == (0, 0):
            self._resolution = (image.shape[1], image.shape[0])
        return image, stamp

    def _queued_max(self) -> int:
        """The most frames the kernel can hold for us: the buffers asked for or, when the driver
        allocated more, the count OpenCV reports back (capped at V4L2's usual 32)."""
        reported = int(self._cap.get(cv2.CAP_PROP_BUFFERSIZE) or 0)
        return min(max(self.config.buffer_size, reported), 32)

    def _grab_fresh(self, t_call: float, deadline: float) -> tuple[np.ndarray, float]:
        cfg = self.config
        not_before = t_call + self._exposure_ms / 1000.0
        # Without monotonic stamps, freshness is counted, never timed: at most `queued` buffers
        # were filled before the call, so the dequeue after them returns a buffer queued after
        # it, and each exposure period that may have begun before that adds one more.
        queued = self._queued_max() + math.ceil(self._exposure_ms / 1000.0 * cfg.fps)
        for dequeued in range(1, queued + self._discard + 7):
            self._grab_once(deadline)
            kernel_ts = self._cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0
            now = time.monotonic()
            on_monotonic = 0.0 < kernel_ts <= now + 0.01 and now - kernel_ts < 5.0
            if self._discard > 0:
                self._discard -= 1
                continue
            if on_monotonic and kernel_ts >= not_before:
                return self._retrieve(), kernel_ts
            if not on_monotonic and dequeued > queued:
                return self._retrieve(), now
        raise DeviceTimeoutError(
            f"{self.name}: only stale frames within the timeout", device=cfg.device
        )

    def _grab_stream(self, t_call: float, deadline: float) -> tuple[np.ndarray, float]:
        """The first frame that arrived one frame period after the call (see module doc)."""
        reader = self._reader
        assert reader is not None
        try:
            got = reader.frame_after(t_call + 1.0 / self.config.fps, deadline)
        except EOFError as exc:
            raise self._mark_lost(str(exc)) from None
        if got is None:
            raise DeviceTimeoutError(
                f"{self.name}: no frame within the timeout (stream stalled? check the camera "
                "and the network)",
                device=self.config.device,
            )
        return _to_bgr(got[0]), got[1]

    def _apply_exposure(self, cap: Any, exposure_ms: float) -> None:
        ok = cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, _V4L2_EXPOSURE_MANUAL) and cap.set(
            cv2.CAP_PROP_EXPOSURE, exposure_ms / _V4L2_EXPOSURE_UNIT_MS
        )
        if not ok:
            raise UnsupportedError(
                f"{self.name} does not accept a manual exposure (api {self.config.api})",
                device=self.config.device,
            )

    def _apply_gain(self, cap: Any, gain: float) -> None:
        if not cap.set(cv2.CAP_PROP_GAIN, gain):
            raise UnsupportedError(
                f"{self.name} does not accept a gain setting (api {self.config.api})",
                device=self.config.device,
            )

    def _connected_cap(self) -> Any:
        if self._cap is None:
            raise DeviceDisconnectedError(
                f"{self.name} is not connected", device=self.config.device
            )
        if self._reader is not None:
            raise UnsupportedError(
                f"{self.name}: a network stream has no exposure or gain control here (set them "
                "in the camera's own web page)",
                device=self.config.device,
            )
        return self._cap

    def get_exposure_ms(self) -> float:
        with self._lock:
            value = self._connected_cap().get(cv2.CAP_PROP_EXPOSURE)
            if value <= 0:
                raise UnsupportedError(
                    f"{self.name} reports no exposure", device=self.config.device
                )
            return float(value) * _V4L2_EXPOSURE_UNIT_MS

    def set_exposure_ms(self, exposure_ms: float) -> None:
        """Manual exposure in ms (the laser stripe wants ~1 ms, the checkerboard ~20 ms)."""
        if not exposure_ms > 0:
            raise UnsupportedError(f"exposure must be > 0 ms, got {exposure_ms}")
        with self._lock:
            self._apply_exposure(self._connected_cap(), exposure_ms)
            self._exposure_ms = exposure_ms
            self._discard = self.config.settle_frames

    def get_gain(self) -> float:
        with self._lock:
            return float(self._connected_cap().get(cv2.CAP_PROP_GAIN))

    def set_gain(self, gain: float) -> None:
        with self._lock:
            self._apply_gain(self._connected_cap(), gain)
            self._gain = gain
            self._discard = self.config.settle_frames


def _first_sequence_file(pattern: str) -> str | None:
    """The first existing file of a printf-style sequence (`img_%03d.png`), or None."""
    if "%" not in pattern:
        return pattern if os.path.exists(pattern) else None
    for i in range(0, 1000):
        try:
            candidate = pattern % i
        except TypeError:
            return None
        if os.path.exists(candidate):
            return candidate
        if i > 5:
            return None
    return None


def _to_bgr(image: np.ndarray) -> np.ndarray:
    """BGR uint8 HxWx3 whatever OpenCV decoded (grey or BGRA files)."""
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    if image.dtype != np.uint8:
        return cv2.convertScaleAbs(image, alpha=255.0 / max(1.0, float(image.max())))
    return image
