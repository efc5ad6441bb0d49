"""The `[service]` and `[logging]` sections of the cell file (the whole file: `config.cell`)."""

from __future__ import annotations

import ipaddress
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from omnisort_hw.config.live_view import LIVE_KEYS, LiveViewConfig
from omnisort_hw.errors import ConfigError

DEFAULT_PORT = 29100
LOOPBACK_NAMES = frozenset({"localhost", "ip6-localhost"})


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and the usual loopback names; anything else is exposed."""
    if host.lower() in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


SERVICE_KEYS = frozenset(
    {
        "host",
        "port",
        "token",
        "token_file",
        "max_line_bytes",
        "max_clients",
        "max_inflight_per_client",
        "max_clients_per_peer",
        "idle_timeout_s",
        "line_timeout_s",
        "write_timeout_s",
        "overflow_grace_s",
        "quick_timeout_s",
        "job_timeout_s",
        "shutdown_timeout_s",
        "capture_keep",
    }
)
LOGGING_KEYS = (
    frozenset({"log_dir", "rerun", "rrd_keep", "rrd_max_total_mb", "rrd_max_file_mb", "level"})
    | LIVE_KEYS
)


def _check_keys(section: Mapping[str, object], name: str, known: frozenset[str]) -> None:
    unknown = sorted(set(section) - known)
    if unknown:
        raise ConfigError(f"[{name}]: unknown key(s) {', '.join(unknown)}")


def _number(section: Mapping[str, object], name: str, key: str, default: float, lo: float) -> float:
    value = section.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or value < lo:
        raise ConfigError(f"[{name}] {key} must be a number >= {lo:g}, got {value!r}")
    return float(value)


def _integer(section: Mapping[str, object], name: str, key: str, default: int, lo: int) -> int:
    value = section.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ConfigError(f"[{name}] {key} must be an integer >= {lo}, got {value!r}")
    return value


def _path(
    section: Mapping[str, object], name: str, key: str, default: str, base: Path | None
) -> Path:
    value = section.get(key, default)
    if not isinstance(value, str) or not value:
        raise ConfigError(f"[{name}] {key} must be a non-empty path string")
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    return path


def client_host(host: str) -> str:
    """Where a client on this PC reaches a service bound to `host` (every address: loopback)."""
    return "127.0.0.1" if host in ("0.0.0.0", "::") else host


def listen_address(section: Mapping[str, object]) -> tuple[str, int]:
    """`[service]` host and port, checked (what the service binds, and its clients read)."""
    host = section.get("host", "127.0.0.1")
    if not isinstance(host, str) or not host:
        raise ConfigError("[service] host must be a non-empty string")
    port = _integer(section, "service", "port", DEFAULT_PORT, 0)
    if port > 65535:
        raise ConfigError(f"[service] port must be in 0..65535, got {port}")
    return host, port


@dataclass(frozen=True)
class ServiceConfig:
    """Where the service listens and how much it accepts."""

    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    token: str | None = None
    max_line_bytes: int = 65536
    max_clients: int = 64
    max_inflight_per_client: int = 8
    max_clients_per_peer: int = 16
    idle_timeout_s: float = 600.0
    line_timeout_s: float = 10.0
    write_timeout_s: float = 10.0
    overflow_grace_s: float = 2.0
    quick_timeout_s: float = 10.0
    job_timeout_s: float = 3600.0
    shutdown_timeout_s: float = 15.0
    capture_keep: int = 50

    @property
    def token_required(self) -> bool:
        """A token is checked when one is configured, and one must be configured off loopback."""
        return self.token is not None or not is_loopback(self.host)

    @classmethod
    def from_mapping(
        cls, section: Mapping[str, object], base_dir: Path | None = None
    ) -> ServiceConfig:
        """Parse `[service]`; a token may come inline (`token`) or from a file (`token_file`)."""
        name = "service"
        _check_keys(section, name, SERVICE_KEYS)
        host, port = listen_address(section)
        token = section.get("token", "")
        if not isinstance(token, str):
            raise ConfigError("[service] token must be a string")
        token_file = section.get("token_file", "")
        if not isinstance(token_file, str):
            raise ConfigError("[service] token_file must be a path string")
        if token and token_file:
            raise ConfigError("[service] set token or token_file, not both")
        if token_file:
            tf = _path(section, name, "token_file", "", base_dir)
            try:
                token = tf.read_text(encoding="utf-8").strip()
            except OSError as exc:
                raise ConfigError(f"[service] token_file {tf}: {exc.strerror or exc}") from None
        if token and len(token) < 16:
            raise ConfigError("[service] token must be at least 16 characters")
        cfg = cls(
            host=host,
            port=port,
            token=token or None,
            max_line_bytes=_integer(section, name, "max_line_bytes", 65536, 1024),
            max_clients=_integer(section, name, "max_clients", 64, 1),
            max_inflight_per_client=_integer(section, name, "max_inflight_per_client", 8, 1),
            max_clients_per_peer=_integer(section, name, "max_clients_per_peer", 16, 1),
            # 0: idle connections are never closed.
            idle_timeout_s=_number(section, name, "idle_timeout_s", 600.0, 0.0),
            line_timeout_s=_number(section, name, "line_timeout_s", 10.0, 0.1),
            write_timeout_s=_number(section, name, "write_timeout_s", 10.0, 0.1),
            overflow_grace_s=_number(section, name, "overflow_grace_s", 2.0, 0.1),
            quick_timeout_s=_number(section, name, "quick_timeout_s", 10.0, 0.1),
            job_timeout_s=_number(section, name, "job_timeout_s", 3600.0, 1.0),
            shutdown_timeout_s=_number(section, name, "shutdown_timeout_s", 15.0, 0.5),
            capture_keep=_integer(section, name, "capture_keep", 50, 1),
        )
        if not is_loopback(cfg.host) and cfg.token is None:
            raise ConfigError(
                f"[service] host = {cfg.host!r} is not loopback: set token or token_file, or bind "
                "to 127.0.0.1"
            )
        return cfg


@dataclass(frozen=True)
class LoggingConfig:
    """Where the per-run `.rrd` files go and how many are kept."""

    log_dir: Path = Path("/var/log/omnisort")
    rerun: bool = True
    rrd_keep: int = 20
    rrd_max_total_mb: float = 2048.0
    rrd_max_file_mb: float = 512.0
    level: str = "INFO"
    live: LiveViewConfig = field(default_factory=LiveViewConfig)

    @classmethod
    def from_mapping(
        cls, section: Mapping[str, object], base_dir: Path | None = None
    ) -> LoggingConfig:
        """Parse `[logging]`."""
        name = "logging"
        _check_keys(section, name, LOGGING_KEYS)
        rerun = section.get("rerun", True)
        if not isinstance(rerun, bool):
            raise ConfigError("[logging] rerun must be true or false")
        level = section.get("level", "INFO")
        if level not in {"DEBUG", "INFO", "WARNING", "ERROR"}:
            raise ConfigError("[logging] level must be DEBUG, INFO, WARNING or ERROR")
        return cls(
            log_dir=_path(section, name, "log_dir", "/var/log/omnisort", base_dir),
            rerun=rerun,
            rrd_keep=_integer(section, name, "rrd_keep", 20, 1),
            rrd_max_total_mb=_number(section, name, "rrd_max_total_mb", 2048.0, 1.0),
            rrd_max_file_mb=_number(section, name, "rrd_max_file_mb", 512.0, 1.0),
            level=level,
            live=LiveViewConfig.from_mapping(section),
        )
