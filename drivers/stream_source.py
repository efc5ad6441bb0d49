"""Network camera streams (IP cameras, the virtual cell) for `V4L2Camera` with `api = "stream"`.

OpenCV's FFMPEG backend reads the stream (MJPEG over HTTP, RTSP); this module checks the URL
and probes the server with a socket timeout first, so a wrong address or a closed port is a
typed error at once instead of FFMPEG's own wait. A stream carries no capture time, so
`StreamReader` reads it all the time and stamps each frame on arrival: a frame that arrived
after `grab()` began plus one frame period was sent after the call (a server that renders or
exposes after a change, as the virtual cell does, then shows the new state).
"""

from __future__ import annotations

import socket
import threading
import time
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

import numpy as np

from drivers.errors import DeviceNotFoundError, DeviceTimeoutError

if TYPE_CHECKING:  # OpenCV is imported by the backend that opens the capture
    import cv2

SCHEMES = {"http": 80, "https": 443, "rtsp": 554}


def is_stream_url(source: str) -> bool:
    """True for http://, https:// and rtsp:// URLs with a host."""
    parts = urlsplit(source)
    return parts.scheme in SCHEMES and bool(parts.hostname)


def probe_stream(url: str, timeout_s: float) -> None:
    """Raise `DeviceNotFoundError` / `DeviceTimeoutError` unless the stream's server accepts a
    TCP connection within `timeout_s`."""
    parts = urlsplit(url)
    host, port = parts.hostname or "", parts.port or SCHEMES.get(parts.scheme, 80)
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except TimeoutError as exc:
        raise DeviceTimeoutError(
            f"camera stream {url}: no answer from {host}:{port} within {timeout_s:.1f} s: check "
            "the camera's power and network",
            device=url,
        ) from exc
    except OSError as exc:
        raise DeviceNotFoundError(
            f"camera stream {url}: cannot connect to {host}:{port} ({exc.strerror or exc}): "
            "check [camera].device and that the camera is on",
            device=url,
        ) from exc


def stream_serial(url: str) -> str:
    """A stable identifier of a network camera: its URL without the query."""
    parts = urlsplit(url)
    return f"stream:{parts.scheme}://{parts.netloc}{parts.path}"


class StreamReader:
    """Reads a network stream continuously in a thread and keeps the latest frame with the time
    it arrived, so the socket never backs up with old frames and `frame_after(t)` can return a
    frame that arrived after `t`. The thread owns the capture and releases it when it ends."""

    def __init__(self, cap: cv2.VideoCapture, name: str) -> None:
        self._cap = cap
        self._cond = threading.Condition()
        self._frame: np.ndarray | None = None
        self._arrived = 0.0
        self._count = 0
        self.failed = ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"stream-{name}", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        cap = self._cap
        try:
            while not self._stop.is_set():
                ok, image = cap.read()
                now = time.monotonic()
                with self._cond:
                    if not ok or image is None:
                        self.failed = "the stream ended or could not be decoded"
                        self._cond.notify_all()
                        return
                    self._frame, self._arrived = image, now
                    self._count += 1
                    self._cond.notify_all()
        finally:
            cap.release()

    def frame_after(self, t: float, deadline: float) -> tuple[np.ndarray, float] | None:
        """The first frame that arrived after `t` (None at the deadline); raises `EOFError`
        when the stream failed."""
        with self._cond:
            while True:
                if self.failed:
                    raise EOFError(self.failed)
                if self._frame is not None and self._arrived > t:
                    return self._frame, self._arrived
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self._cond.wait(min(remaining, 0.1))

    def stop(self, wait_s: float = 2.0) -> bool:
        """Ask the thread to end (it finishes its current read, then releases the capture) and
        wait up to `wait_s` for it; False when it is still blocked in a read (a stream that
        sends nothing until the scene changes)."""
        self._stop.set()
        self._thread.join(wait_s)
        return not self._thread.is_alive()
