"""The cell file, loaded once at start into one typed record (`CellConfig`).

Every section is parsed and validated here, so a wrong key stops `omnisort serve` (and every
command that reads the file) at start with the file and the key in the message:

    [service] [logging]          -> omnisort_hw.config.service
    [storage]                    -> omnisort_hw.config.storage.StorageConfig
    [camera] [laser] [arm]       -> omnisort_hw.config.devices
    [sorting] [registration]     -> omnisort_hw.config.sorting
    [target]                     -> TargetConfig (the extrinsic calibration's defaults)
    [ui]                         -> omnisort_hw.config.ui.UiConfig (the operator interface)

Relative paths resolve against the file's own folder, never the working directory (systemd
starts the service from /).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from omnisort_hw.config.capture import CaptureSettings, capture_settings
from omnisort_hw.config.devices import CellDeviceConfig, parse_device_config
from omnisort_hw.config.service import LoggingConfig, ServiceConfig
from omnisort_hw.config.sorting import (
    RegistrationConfig,
    SortSection,
    parse_registration_config,
    parse_sort_section,
)
from omnisort_hw.config.storage import StorageConfig
from omnisort_hw.config.target import separation_problem
from omnisort_hw.config.toml_file import read_toml
from omnisort_hw.config.ui import UiConfig
from omnisort_hw.config.watchdog import PlcConfig, WatchdogConfig
from omnisort_hw.core.choices import TARGETS
from omnisort_hw.errors import ConfigError

SECTIONS = (
    "service",
    "storage",
    "logging",
    "camera",
    "laser",
    "arm",
    "target",
    "sorting",
    "registration",
    "watchdog",
    "plc",
    "capture",
    "ui",
)


TARGET_KEYS = frozenset({"kind", "separation_mm"})


@dataclass(frozen=True)
class TargetConfig:
    """`[target]`: the calibration target's kind and wall separation (mm), as defaults for
    `calibrate what=extrinsics`."""

    kind: str | None = None
    separation_mm: float | None = None

    @classmethod
    def from_mapping(cls, section: Mapping[str, object]) -> TargetConfig:
        unknown = sorted(set(section) - TARGET_KEYS)
        if unknown:
            known = ", ".join(sorted(TARGET_KEYS))
            raise ConfigError(f"[target].{unknown[0]}: unknown key (known: {known})")
        kind = section.get("kind")
        if kind is not None and (not isinstance(kind, str) or kind not in TARGETS):
            raise ConfigError(f"[target].kind: one of {', '.join(TARGETS)}, got {kind!r}")
        sep = section.get("separation_mm")
        if sep is None:
            return cls(kind, None)
        problem = separation_problem(sep)
        if problem or not isinstance(sep, int | float):
            raise ConfigError(f"[target].separation_mm: {problem}")
        return cls(kind, float(sep))


@dataclass(frozen=True)
class CellConfig:
    """Every section of the cell file, parsed; `path` is the file (None when built in code)."""

    path: Path | None = None
    service: ServiceConfig = field(default_factory=ServiceConfig)
    storage: StorageConfig = field(default_factory=lambda: StorageConfig.from_mapping({}))
    logging: LoggingConfig = field(default_factory=LoggingConfig)
    devices: CellDeviceConfig = field(default_factory=CellDeviceConfig)
    target: TargetConfig = field(default_factory=TargetConfig)
    sorting: SortSection | None = None
    registration: RegistrationConfig | None = None
    watchdog: WatchdogConfig = field(default_factory=WatchdogConfig)
    plc: PlcConfig = field(default_factory=PlcConfig)
    capture: CaptureSettings = field(default_factory=CaptureSettings)
    ui: UiConfig = field(default_factory=UiConfig)

    @property
    def base_dir(self) -> Path | None:
        """The folder relative paths of the file are resolved against."""
        return self.path.parent if self.path is not None else None

    @classmethod
    def from_mapping(cls, doc: Mapping[str, object], path: Path | None = None) -> CellConfig:
        """Parse a TOML document already loaded; relative paths are relative to its folder."""
        base = path.parent if path is not None else None
        unknown = sorted(set(doc) - set(SECTIONS))
        if unknown:
            raise ConfigError(f"[{unknown[0]}]: unknown section (known: {', '.join(SECTIONS)})")
        tables: dict[str, Mapping[str, object]] = {}
        for key in SECTIONS:
            value = doc.get(key, {})
            if not isinstance(value, Mapping):
                raise ConfigError(f"[{key}] must be a table")
            tables[key] = value
        return cls(
            path=path,
            service=ServiceConfig.from_mapping(tables["service"], base),
            storage=StorageConfig.from_mapping(tables["storage"], base),
            logging=LoggingConfig.from_mapping(tables["logging"], base),
            devices=parse_device_config(doc, base),
            target=TargetConfig.from_mapping(tables["target"]),
            sorting=parse_sort_section(doc["sorting"], base) if "sorting" in doc else None,
            registration=(
                parse_registration_config(tables["registration"]) if "registration" in doc else None
            ),
            watchdog=WatchdogConfig.from_mapping(tables["watchdog"]),
            plc=PlcConfig.from_mapping(tables["plc"]),
            capture=capture_settings(tables["capture"]),
            ui=UiConfig.from_mapping(tables["ui"]),
        )


def load_cell_config(path: str | Path) -> CellConfig:
    """Read and validate the cell file; ConfigError names the file and the key."""
    p = Path(path)
    doc = read_toml(p, "cell configuration file")
    try:
        return CellConfig.from_mapping(doc, p.resolve())
    except ConfigError as exc:
        err = ConfigError(f"{p}: {exc}")
        err.key = getattr(exc, "key", None)  # type: ignore[attr-defined]
        raise err from None


def section_keys() -> dict[str, frozenset[str]]:
    """Every key the loader reads in each section but the device sections (whose keys are
    their backend's config dataclass, or `devices.SIM_SETTINGS`): what deploy/cell.example.toml
    must document."""
    from dataclasses import fields

    from omnisort_hw.config.capture import CaptureSettings
    from omnisort_hw.config.service import LOGGING_KEYS, SERVICE_KEYS
    from omnisort_hw.config.sorting import REGISTRATION_KEYS, SORT_KEYS
    from omnisort_hw.config.storage import STORAGE_KEYS
    from omnisort_hw.config.ui import UI_KEYS
    from omnisort_hw.config.watchdog import PLC_KEYS, WATCHDOG_KEYS

    return {
        "service": SERVICE_KEYS,
        "storage": STORAGE_KEYS,
        "logging": LOGGING_KEYS,
        "target": TARGET_KEYS,
        "sorting": frozenset(SORT_KEYS),
        "registration": REGISTRATION_KEYS,
        "watchdog": WATCHDOG_KEYS,
        "plc": PLC_KEYS,
        "capture": frozenset(f.name for f in fields(CaptureSettings)),
        "ui": UI_KEYS,
    }
