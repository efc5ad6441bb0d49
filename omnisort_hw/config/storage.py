"""The `[storage]` section of the cell file: where the calibration store lives and its rules."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from omnisort_hw.errors import ConfigError

STORAGE_KEYS = frozenset({"state_dir", "max_age_days", "history_keep", "camera_serial"})


@dataclass(frozen=True)
class StorageConfig:
    """The `[storage]` section of the cell configuration."""

    state_dir: Path
    max_age_days: float | None = None
    history_keep: int = 20
    camera_serial: str | None = None

    @classmethod
    def from_mapping(
        cls, section: Mapping[str, object], base_dir: Path | None = None
    ) -> StorageConfig:
        """Build from a parsed TOML section; relative paths are taken from `base_dir`."""
        unknown = sorted(set(section) - STORAGE_KEYS)
        if unknown:
            raise ConfigError(f"[storage]: unknown key(s) {', '.join(unknown)}")
        raw_dir = section.get("state_dir", "/var/lib/omnisort")
        if not isinstance(raw_dir, str) or not raw_dir:
            raise ConfigError("[storage] state_dir must be a non-empty path string")
        state_dir = Path(raw_dir).expanduser()
        if not state_dir.is_absolute() and base_dir is not None:
            state_dir = base_dir / state_dir
        age = section.get("max_age_days", 0)
        if isinstance(age, bool) or not isinstance(age, int | float) or age < 0:
            raise ConfigError("[storage] max_age_days must be a number >= 0 (0: no age limit)")
        keep = section.get("history_keep", 20)
        if isinstance(keep, bool) or not isinstance(keep, int) or keep < 0:
            raise ConfigError("[storage] history_keep must be an integer >= 0")
        serial = section.get("camera_serial", "")
        if not isinstance(serial, str):
            raise ConfigError("[storage] camera_serial must be a string ('' : use the camera's)")
        return cls(
            state_dir=state_dir,
            max_age_days=float(age) or None,
            history_keep=keep,
            camera_serial=serial or None,
        )
