"""`[ui]`: the operator interface (`omnisort ui`), a separate process and a client of the
service (docs/operator_ui.md)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from omnisort_hw.config.service import client_host, listen_address
from omnisort_hw.config.toml_file import read_toml
from omnisort_hw.config.watchdog import _bool, _num, _unknown
from omnisort_hw.errors import ConfigError

UI_KEYS = frozenset(
    {
        "host",
        "port",
        "allow_operator",
        "status_period_s",
        "view_period_s",
        "view_width_px",
        "sim_control",
    }
)
DEFAULT_UI_PORT = 29180


@dataclass(frozen=True)
class UiConfig:
    """Where the interface listens (loopback unless set), whether it offers operator actions
    at all (`allow_operator = false`: a view-only screen), how often it reads the service's
    status and grabs the live view, and the live view's width in pixels. `sim_control`
    ("HOST:PORT") is the virtual cell's control channel: set, the page has a Simulator tab
    (docs/virtual_cell.md); the service never learns of it."""

    host: str = "127.0.0.1"
    port: int = DEFAULT_UI_PORT
    allow_operator: bool = True
    status_period_s: float = 0.5
    view_period_s: float = 0.5
    view_width_px: int = 960
    sim_control: tuple[str, int] | None = None

    @classmethod
    def from_mapping(cls, section: Mapping[str, object]) -> UiConfig:
        n = "ui"
        _unknown(section, n, UI_KEYS)
        host = section.get("host", "127.0.0.1")
        if not isinstance(host, str) or not host:
            raise ConfigError(f"[ui] host must be an address string, got {host!r}")
        port = section.get("port", DEFAULT_UI_PORT)
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ConfigError(f"[ui] port must be an integer in [0, 65535], got {port!r}")
        width = section.get("view_width_px", 960)
        if isinstance(width, bool) or not isinstance(width, int) or not 64 <= width <= 4096:
            raise ConfigError(f"[ui] view_width_px must be an integer in [64, 4096], got {width!r}")
        return cls(
            host=host,
            port=port,
            allow_operator=_bool(section, n, "allow_operator", True),
            status_period_s=_num(section, n, "status_period_s", 0.5, 0.05, 60.0),
            view_period_s=_num(section, n, "view_period_s", 0.5, 0.05, 60.0),
            view_width_px=width,
            sim_control=_address(section.get("sim_control")),
        )


def _address(value: object) -> tuple[str, int] | None:
    """`[ui] sim_control` as (host, port); None when unset."""
    if value is None:
        return None
    host, _, port = str(value).rpartition(":") if isinstance(value, str) else ("", "", "")
    if not host or not port.isdigit() or not 0 < int(port) <= 65535:
        raise ConfigError(f'[ui] sim_control must be "HOST:PORT", got {value!r}')
    return host, int(port)


@dataclass(frozen=True)
class UiSettings:
    """What `omnisort ui` reads of the cell file: its own section and where the service is."""

    ui: UiConfig
    service_host: str
    service_port: int


def load_ui_settings(path: str | Path) -> UiSettings:
    """`[ui]`, and `[service]` host and port, of the cell file. Nothing else is read: the
    interface never needs the service token (`token_file` is not opened), the devices or the
    calibration, and its systemd unit gives it a copy of the cell file alone."""
    p = Path(path)
    doc = read_toml(p, "cell configuration file")
    try:
        section = doc.get("ui", {})
        service = doc.get("service", {})
        if not isinstance(section, Mapping) or not isinstance(service, Mapping):
            raise ConfigError("[ui] and [service] must be tables")
        ui = UiConfig.from_mapping(section)
        host, port = listen_address(service)
        if port == 0:
            raise ConfigError("[service] port 0 (any free port) cannot be reached: set it")
    except ConfigError as exc:
        raise ConfigError(f"{p}: {exc}") from None
    return UiSettings(ui, client_host(host), port)
