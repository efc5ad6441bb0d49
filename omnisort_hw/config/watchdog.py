"""`[watchdog]` (calibration drift) and `[plc]` (Modbus TCP face) sections of the cell file."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from omnisort_hw.config.service import is_loopback
from omnisort_hw.errors import ConfigError

WATCHDOG_KEYS = frozenset({"period_s", "before_sort", "false_alarm_rate", "min_angle_deg"})
PLC_KEYS = frozenset({"modbus_port", "host", "allow_commands"})


def _unknown(section: Mapping[str, object], name: str, known: frozenset[str]) -> None:
    extra = sorted(set(section) - known)
    if extra:
        raise ConfigError(f"[{name}].{extra[0]}: unknown key (known: {', '.join(sorted(known))})")


def _num(
    section: Mapping[str, object], name: str, key: str, default: float, lo: float, hi: float
) -> float:
    v = section.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int | float) or not lo <= v <= hi:
        raise ConfigError(f"[{name}] {key} must be a number in [{lo:g}, {hi:g}], got {v!r}")
    return float(v)


def _bool(section: Mapping[str, object], name: str, key: str, default: bool) -> bool:
    v = section.get(key, default)
    if not isinstance(v, bool):
        raise ConfigError(f"[{name}] {key} must be true or false, got {v!r}")
    return v


@dataclass(frozen=True)
class WatchdogConfig:
    """`[watchdog]`: period of the automatic check (0: only on request and before `sort`),
    whether `sort` checks first, the false-alarm rate of one check and the smallest angle ever
    called drift (docs/drift.md)."""

    period_s: float = 600.0
    before_sort: bool = True
    false_alarm_rate: float = 1e-6
    min_angle_deg: float = 0.02

    @classmethod
    def from_mapping(cls, section: Mapping[str, object]) -> WatchdogConfig:
        n = "watchdog"
        _unknown(section, n, WATCHDOG_KEYS)
        return cls(
            period_s=_num(section, n, "period_s", 600.0, 0.0, 86400.0),
            before_sort=_bool(section, n, "before_sort", True),
            false_alarm_rate=_num(section, n, "false_alarm_rate", 1e-6, 1e-12, 0.1),
            min_angle_deg=_num(section, n, "min_angle_deg", 0.02, 0.0, 10.0),
        )


@dataclass(frozen=True)
class PlcConfig:
    """`[plc]`: the Modbus TCP server (off when `modbus_port` is absent; 0 = any free port),
    its bind address (loopback unless set) and whether coils may command the cell."""

    modbus_port: int | None = None
    host: str = "127.0.0.1"
    allow_commands: bool = False

    @classmethod
    def from_mapping(cls, section: Mapping[str, object]) -> PlcConfig:
        n = "plc"
        _unknown(section, n, PLC_KEYS)
        port = section.get("modbus_port")
        if port is not None and (
            isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535
        ):
            raise ConfigError(f"[plc] modbus_port must be an integer in [0, 65535], got {port!r}")
        host = section.get("host", "127.0.0.1")
        if not isinstance(host, str) or not host:
            raise ConfigError(f"[plc] host must be an address string, got {host!r}")
        return cls(port, host, _bool(section, n, "allow_commands", False))

    @property
    def on_loopback(self) -> bool:
        return is_loopback(self.host)
