"""The `[capture]` section of the cell file: how a measurement is captured (frames, exposure,
gain, retries, differencing)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from omnisort_hw.errors import ConfigError, InputError


@dataclass(frozen=True)
class CaptureSettings:
    """`[capture]` of the cell file: frames per kind, exposure and gain per task, retries."""

    frames: int = 8
    stripe_exposure_ms: float = 6.0
    stripe_gain: float = 1.0
    board_exposure_ms: float = 10.0
    board_gain: float = 1.0
    max_retries: int = 4
    clipped_limit: float = 0.02
    prefer_uncompressed: bool = True
    differencing: bool = True

    def __post_init__(self) -> None:
        checks = {
            "frames": 1 <= self.frames <= 64,
            "stripe_exposure_ms": self.stripe_exposure_ms > 0,
            "board_exposure_ms": self.board_exposure_ms > 0,
            "stripe_gain": self.stripe_gain > 0,
            "board_gain": self.board_gain > 0,
            "max_retries": 0 <= self.max_retries <= 10,
            "clipped_limit": 0 <= self.clipped_limit < 1,
        }
        for key, ok in checks.items():
            if not ok:
                raise InputError(f"[capture].{key} = {getattr(self, key)!r} is out of range")


def capture_settings(section: Any) -> CaptureSettings:
    """`[capture]` of the cell file; ConfigError names an unknown key or a bad value."""
    known = {f.name: f.type for f in fields(CaptureSettings)}
    values: dict[str, Any] = {}
    for key, value in dict(section).items():
        if key not in known:
            raise ConfigError(f"[capture].{key}: unknown key (known: {', '.join(known)})")
        want = {"int": int, "float": float, "bool": bool}[str(known[key])]
        if want is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, want) or (want is int and isinstance(value, bool)):
            raise ConfigError(f"[capture].{key}: expected {want.__name__}, got {value!r}")
        values[key] = value
    try:
        return CaptureSettings(**values)
    except InputError as exc:
        raise ConfigError(str(exc)) from None
