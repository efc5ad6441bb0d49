"""Any exception as the protocol's error: its code, message and details (the drivers'
device errors keep their device code; anything unknown is `internal`)."""

from __future__ import annotations

from typing import Any

from omnisort_hw.errors import IO_ERROR, OmnisortError
from omnisort_hw.fileio import os_error_text
from omnisort_hw.service import protocol as proto


def error_from_exception(exc: BaseException) -> tuple[str, str, dict[str, Any]]:
    """Map any exception to (protocol code, message, details); unknown ones are `internal`."""
    if isinstance(exc, proto.ProtocolError):
        return exc.code, exc.message, dict(exc.details)
    if isinstance(exc, OmnisortError):
        return exc.code, str(exc), {}
    code = getattr(exc, "code", None)
    if _is_device_error(exc) and isinstance(code, str):
        details: dict[str, Any] = {"device_code": code}
        if getattr(exc, "device", None):
            details["device"] = exc.device  # type: ignore[attr-defined]
        if code == "motion_refused":
            return proto.MOTION_REFUSED, str(exc), details
        return proto.DEVICE_ERROR, str(exc), details
    if isinstance(exc, OSError) and exc.filename:
        return IO_ERROR, os_error_text(exc), {"path": str(exc.filename)}
    return proto.INTERNAL, f"internal error ({type(exc).__name__}): {exc}", {}


def _is_device_error(exc: BaseException) -> bool:
    try:
        from drivers.errors import DeviceError
    except ImportError:
        return isinstance(getattr(exc, "code", None), str)
    return isinstance(exc, DeviceError)
