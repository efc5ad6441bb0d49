"""`omnisort serve` refuses a start that cannot work before it opens any device. The laser is
a TCP peer (Modbus) listening here: a refused start must never connect to it."""

from __future__ import annotations

import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def laser_peer() -> Iterator[socket.socket]:
    """A listening socket standing in for the Modbus laser: its backlog shows a connection."""
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(8)
    sock.setblocking(False)
    yield sock
    sock.close()


def _connected(peer: socket.socket) -> bool:
    try:
        conn, _ = peer.accept()
    except BlockingIOError:
        return False
    conn.close()
    return True


def _busy_port() -> socket.socket:
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen(1)
    return sock


def _serve(tmp_path: Path, laser_port: int, extra: str, *args: str) -> subprocess.CompletedProcess:
    cfg = tmp_path / "cell.toml"
    cfg.write_text(
        f'[laser]\nbackend = "modbus"\ntcp_port = {laser_port}\ncoil = 2\ntimeout_s = 0.5\n'
        f'[storage]\nstate_dir = "state"\n[logging]\nlog_dir = "logs"\n{extra}'
    )
    return subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "serve", "--config", str(cfg), *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
    )


def test_a_port_in_use_is_refused_before_the_devices_open(tmp_path, laser_peer) -> None:
    with _busy_port() as busy:
        port = busy.getsockname()[1]
        proc = _serve(tmp_path, laser_peer.getsockname()[1], f"[service]\nport = {port}\n")
    assert proc.returncode == 2, proc.stderr
    assert "[address_in_use]" in proc.stderr and f"127.0.0.1:{port} is already in use" in (
        proc.stderr
    )
    assert not _connected(laser_peer)


def test_the_plc_port_in_use_is_refused_before_the_devices_open(tmp_path, laser_peer) -> None:
    with _busy_port() as busy:
        port = busy.getsockname()[1]
        extra = f"[service]\nport = 0\n[plc]\nmodbus_port = {port}\n"
        proc = _serve(tmp_path, laser_peer.getsockname()[1], extra)
    assert proc.returncode == 2, proc.stderr
    assert "[plc] modbus_port" in proc.stderr and "already in use" in proc.stderr
    assert not _connected(laser_peer)


def test_a_port_given_twice_is_a_config_error_before_the_devices_open(tmp_path, laser_peer) -> None:
    with socket.socket() as free:
        free.bind(("127.0.0.1", 0))
        port = free.getsockname()[1]
    extra = f"[service]\nport = {port}\n[plc]\nmodbus_port = {port}\n"
    proc = _serve(tmp_path, laser_peer.getsockname()[1], extra)
    assert proc.returncode == 78, proc.stderr
    assert f"[plc] modbus_port: port {port} is also [service] port" in proc.stderr
    assert not _connected(laser_peer)


def test_an_exposed_address_without_a_token_is_refused_first(tmp_path, laser_peer) -> None:
    """Exit 78 (EX_CONFIG): the unit's RestartPreventExitStatus keeps systemd from retrying."""
    proc = _serve(tmp_path, laser_peer.getsockname()[1], "", "--host", "0.0.0.0", "--port", "0")
    assert proc.returncode == 78, proc.stderr
    assert "[bad_config]" in proc.stderr and "without a token" in proc.stderr
    assert not _connected(laser_peer)
    unit = (Path(__file__).parents[2] / "deploy" / "omnisort.service").read_text()
    assert "RestartPreventExitStatus=78" in unit


def test_a_port_out_of_range_is_a_config_error(tmp_path, laser_peer) -> None:
    proc = _serve(tmp_path, laser_peer.getsockname()[1], "", "--port", "70000")
    assert proc.returncode == 78, proc.stderr
    assert "70000" in proc.stderr and not _connected(laser_peer)


def test_the_same_cell_starts_when_nothing_is_wrong(tmp_path, laser_peer) -> None:
    """The control case: with a free port the service does open its laser (and then fails on
    this stand-in, which speaks no Modbus), so the refusals above are not an artefact."""
    proc = _serve(tmp_path, laser_peer.getsockname()[1], "[service]\nport = 0\n")
    assert proc.returncode != 0
    assert _connected(laser_peer), proc.stderr


def test_an_address_not_on_this_machine_is_retried_not_a_config_error() -> None:
    """At boot the cell's address may not be up yet: exit 2 (systemd retries), not 78. The
    bind is refused locally (TEST-NET-1 is on no interface); nothing is sent."""
    from omnisort_hw.errors import ConfigError
    from omnisort_hw.service.listener import AddressError, probe

    with pytest.raises(AddressError, match="no such address") as info:
        probe("192.0.2.1", 0, "[service] host")
    assert info.value.exit_code == 2 and not isinstance(info.value, ConfigError)
