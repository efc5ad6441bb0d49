"""What `serve` checks before it opens a device: the exposure rule (off loopback a token is
required) and every address it will listen on (the protocol, the PLC face, the live view and
its web viewer), so a port in use or taken twice is refused before the camera, laser and arm
are opened (under systemd's restart policy a late refusal opened the arm once per restart).

A wrong setting is a ConfigError (exit 78: systemd does not retry it); a port in use or an
address not there yet (the network still coming up at boot) is an AddressError (exit 2: the
unit's Restart=on-failure tries again)."""

from __future__ import annotations

import errno
import socket
from collections.abc import Iterable

from omnisort_hw.config.cell import CellConfig
from omnisort_hw.config.service import ServiceConfig, is_loopback
from omnisort_hw.errors import ConfigError, OmnisortError

# Resolver failures that pass by themselves (DNS not reachable yet at boot).
_TRANSIENT_GAI = {socket.EAI_AGAIN} | (
    {socket.EAI_NODATA} if hasattr(socket, "EAI_NODATA") else set()
)


class AddressError(OmnisortError):
    """A listening address of the service is taken, or not available on this machine yet."""

    code = "address_in_use"


def check_exposure(config: ServiceConfig) -> None:
    """Off loopback the protocol can move the arm: refuse to listen there without a token."""
    if not is_loopback(config.host) and config.token is None:
        raise ConfigError(
            f"refusing to listen on {config.host!r} without a token; set [service] token "
            "or token_file, or listen on 127.0.0.1"
        )


def addresses(settings: CellConfig, service: ServiceConfig) -> list[tuple[str, int, str]]:
    """Every (host, port, setting) the service will listen on; port 0 is any free port."""
    out = [(service.host, service.port, "[service] port")]
    if settings.plc.modbus_port is not None:
        out.append((settings.plc.host, settings.plc.modbus_port, "[plc] modbus_port"))
    view = settings.logging.live
    if view.enabled:
        out.append((view.host, view.port, "[logging] live_port"))
        if view.web_port is not None:
            out.append((view.host, view.web_port, "[logging] live_web_port"))
    return out


def probe(host: str, port: int, what: str) -> None:
    """Bind and release (host, port) on every address the host resolves to, as the server
    will; a typed error names `what` and the address otherwise."""
    if not 0 <= port <= 65535:
        raise ConfigError(f"{what}: port {port} is outside 0-65535")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        error = AddressError if exc.errno in _TRANSIENT_GAI else ConfigError
        raise error(f"{what}: cannot resolve host {host!r} ({exc.strerror})") from None
    for family, kind, proto, _, addr in infos:
        with socket.socket(family, kind, proto) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                sock.bind(addr)
            except OSError as exc:
                raise _bind_error(exc, what, host, port) from None


def _bind_error(exc: OSError, what: str, host: str, port: int) -> OmnisortError:
    where = f"{what}: {host}:{port}"
    if exc.errno == errno.EADDRINUSE:
        return AddressError(
            f"{where} is already in use (another omnisort or another program listens "
            "there; `ss -ltnp` shows which)"
        )
    if exc.errno == errno.EADDRNOTAVAIL:
        return AddressError(f"{where}: no such address on this machine (yet?): {exc.strerror}")
    return ConfigError(f"{where}: cannot listen there ({exc.strerror})")


def preflight(settings: CellConfig, service: ServiceConfig) -> None:
    """The exposure rule, no port configured twice, and every listening address free."""
    check_exposure(service)
    listed = addresses(settings, service)
    seen: dict[int, str] = {}
    for _, port, what in listed:
        if port and port in seen:
            raise ConfigError(f"{what}: port {port} is also {seen[port]}; give each its own")
        seen[port] = what
    probe_all(listed)


def probe_all(listed: Iterable[tuple[str, int, str]]) -> None:
    for host, port, what in listed:
        probe(host, port, what)
