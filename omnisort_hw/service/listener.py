"""What `serve` checks before it opens a device: the exposure rule (off loopback a token is
required) and the listening addresses, bound or probed here so a port in use is refused
before the camera, laser and arm are opened (under systemd's restart policy a late refusal
opened the arm once per restart)."""

from __future__ import annotations

import errno
import socket
from collections.abc import Iterable

from omnisort_hw.config.service import ServiceConfig, is_loopback
from omnisort_hw.errors import ConfigError, OmnisortError


class AddressInUseError(OmnisortError):
    """A listening address of the service is taken (another process, or an old instance)."""

    code = "address_in_use"


def check_exposure(config: ServiceConfig) -> None:
    """Off loopback the protocol can move the arm: refuse to listen there without a token."""
    if not is_loopback(config.host) and config.token is None:
        raise ConfigError(
            f"refusing to listen on {config.host!r} without a token; set [service] token "
            "or token_file, or listen on 127.0.0.1"
        )


def _bind(host: str, port: int, what: str) -> socket.socket:
    """A TCP socket bound to (host, port), or a typed error naming `what` and the address."""
    if not 0 <= port <= 65535:
        raise ConfigError(f"{what}: port {port} is outside 0-65535")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise ConfigError(f"{what}: cannot resolve host {host!r} ({exc})") from None
    family, kind, proto, _, addr = infos[0]
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(addr)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise AddressInUseError(
                f"{what}: {host}:{port} is already in use (another omnisort or another "
                "program listens there; `ss -ltnp` shows which)"
            ) from None
        raise ConfigError(f"{what}: cannot listen on {host}:{port} ({exc.strerror})") from None
    return sock


def bind_listener(config: ServiceConfig) -> socket.socket:
    """The protocol's listening socket, bound and listening, for `asyncio.start_server(sock=)`."""
    sock = _bind(config.host, config.port, "[service] port")
    sock.listen(128)
    sock.setblocking(False)
    return sock


def probe_ports(addresses: Iterable[tuple[str, int, str]]) -> None:
    """Bind and release each (host, port, what) that a later part of start-up will listen on
    (PLC face, live view); port 0 asks for any free port and is always available."""
    for host, port, what in addresses:
        if port:
            _bind(host, port, what).close()
