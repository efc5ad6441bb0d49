"""Network camera streams (IP cameras, the virtual cell) for `V4L2Camera` with `api = "stream"`.

OpenCV's FFMPEG backend reads the stream (MJPEG over HTTP, RTSP); this module checks the URL
and probes the server with a socket timeout first, so a wrong address or a closed port is a
typed error at once instead of FFMPEG's own wait.
"""

from __future__ import annotations

import socket
from urllib.parse import urlsplit

from drivers.errors import DeviceNotFoundError, DeviceTimeoutError

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
