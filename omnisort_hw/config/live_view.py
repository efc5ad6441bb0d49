"""The live-view keys of `[logging]`: stream what the service logs to a rerun gRPC server."""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from omnisort_hw.errors import ConfigError

LIVE_KEYS = frozenset({"live", "live_host", "live_port", "live_web_port", "live_memory_limit"})
_MEMORY = re.compile(r"^\d+(\.\d+)?\s*(B|KiB|MiB|GiB|KB|MB|GB|%)$")


@dataclass(frozen=True)
class LiveViewConfig:
    """`live = true` serves the run log on gRPC at live_host:live_port (loopback unless set);
    `live_web_port` also serves rerun's web viewer; the server keeps at most
    `live_memory_limit` of data and drops the oldest beyond it (docs/live_view.md)."""

    enabled: bool = False
    host: str = "127.0.0.1"
    port: int = 9876
    web_port: int | None = None
    memory_limit: str = "256MiB"

    @classmethod
    def from_mapping(cls, section: Mapping[str, object]) -> LiveViewConfig:
        live = section.get("live", False)
        if not isinstance(live, bool):
            raise ConfigError(f"[logging] live must be true or false, got {live!r}")
        host = section.get("live_host", "127.0.0.1")
        if not isinstance(host, str) or not host:
            raise ConfigError(f"[logging] live_host must be an address string, got {host!r}")
        ports = {}
        for key, default in (("live_port", 9876), ("live_web_port", None)):
            v = section.get(key, default)
            if v is not None and (
                isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 65535
            ):
                raise ConfigError(f"[logging] {key} must be an integer in [0, 65535], got {v!r}")
            ports[key] = v
        limit = section.get("live_memory_limit", "256MiB")
        if not isinstance(limit, str) or not _MEMORY.match(limit):
            raise ConfigError(
                f"[logging] live_memory_limit must look like 256MiB, 1GiB or 25%, got {limit!r}"
            )
        port = ports["live_port"]
        if port is None:
            raise ConfigError("[logging] live_port must be an integer in [0, 65535], got None")
        return cls(live, host, port, ports["live_web_port"], limit)
