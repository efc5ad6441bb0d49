"""Modbus laser switch against real pymodbus servers: TCP on 127.0.0.1, RTU over a pty pair."""

from __future__ import annotations

import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from pymodbus.client import ModbusTcpClient

from drivers.errors import (
    BadReplyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceNotFoundError,
    DeviceTimeoutError,
)
from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
from tests.drivers.contract import LaserSwitchContract
from tests.drivers.modbus_peer import ModbusTestServer, PtyBridge, free_tcp_port

pytestmark = pytest.mark.timeout(20)

TIMEOUT = 0.3
ANSWER_S = 5.0
"""The device timeout of a test that asks a working peer (a round trip): a guard, not a bound
on its latency. Over the pty bridge and the in-process server, a loaded runner took more than
TIMEOUT to answer; the tests of timeouts themselves keep TIMEOUT."""
COIL = 5
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def tcp_server() -> Iterator[ModbusTestServer]:
    server = ModbusTestServer()
    yield server
    server.stop()


@pytest.fixture
def rtu_pair() -> Iterator[tuple[ModbusTestServer, str]]:
    bridge = PtyBridge()
    server = ModbusTestServer(serial_port=bridge.a)
    yield server, bridge.b
    server.stop()
    bridge.close()


def tcp_laser(port: int, **overrides: object) -> ModbusLaser:
    settings: dict[str, object] = {"tcp_port": port, "coil": COIL, "timeout_s": TIMEOUT}
    settings.update(overrides)
    return ModbusLaser(ModbusLaserConfig(**settings))  # type: ignore[arg-type]


def rtu_laser(path: str, **overrides: object) -> ModbusLaser:
    settings: dict[str, object] = {
        "transport": "rtu",
        "serial_port": path,
        "baudrate": 115200,
        "coil": COIL,
        "timeout_s": TIMEOUT,
    }
    settings.update(overrides)
    return ModbusLaser(ModbusLaserConfig(**settings))  # type: ignore[arg-type]


def read_coil_independently(port: int, coil: int) -> bool:
    """Ask the server with a separate pymodbus client: did the coil really change?"""
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=1.0, retries=0)
    assert client.connect()
    try:
        return bool(client.read_coils(coil, count=1, device_id=1).bits[0])
    finally:
        client.close()


class TestModbusTcpLaserContract(LaserSwitchContract):
    @pytest.fixture
    def make_laser(self, tcp_server: ModbusTestServer):
        return lambda: tcp_laser(tcp_server.port)


class TestModbusRtuLaserContract(LaserSwitchContract):
    @pytest.fixture
    def make_laser(self, rtu_pair: tuple[ModbusTestServer, str]):
        return lambda: rtu_laser(rtu_pair[1])


def test_tcp_switch_changes_the_coil_on_the_server(tcp_server) -> None:
    with tcp_laser(tcp_server.port, timeout_s=ANSWER_S) as laser:
        laser.on()
        assert read_coil_independently(tcp_server.port, COIL) is True
        assert read_coil_independently(tcp_server.port, COIL + 1) is False
        laser.off()
        assert read_coil_independently(tcp_server.port, COIL) is False


def test_nothing_listening_is_device_not_found_quickly() -> None:
    port = free_tcp_port()
    t0 = time.monotonic()
    with pytest.raises(DeviceNotFoundError, match=f"127.0.0.1:{port}"):
        tcp_laser(port).connect()
    assert time.monotonic() - t0 < 2 * TIMEOUT + 0.5


def test_coil_outside_the_device_is_an_exception_response(tcp_server) -> None:
    laser = tcp_laser(tcp_server.port, coil=500)
    with pytest.raises(
        BadReplyError, match=r"exception 2 \(ILLEGAL DATA ADDRESS\).*\[laser\]\.coil"
    ):
        laser.connect()
    assert not laser.is_connected


def test_silent_tcp_peer_is_a_timeout_within_the_bound() -> None:
    import socket

    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen()
        port = listener.getsockname()[1]
        laser = tcp_laser(port, retries=1)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match="did not answer"):
            laser.connect()
        elapsed = time.monotonic() - t0
    assert 2 * TIMEOUT * 0.9 <= elapsed < 2 * TIMEOUT + 1.0


def test_server_going_away_is_a_disconnection_within_the_timeout(tcp_server) -> None:
    laser = tcp_laser(tcp_server.port)
    laser.connect()
    laser.on()
    tcp_server.stop()
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnectedError, match="connection lost"):
        laser.off()
    with pytest.raises(DeviceDisconnectedError):
        laser.state()
    assert time.monotonic() - t0 < 2 * TIMEOUT + 0.5
    assert not laser.is_connected
    laser.close()


def test_server_process_killed_then_restarted_is_survived() -> None:
    """A separate server process is killed (SIGKILL) and restarted on the same port."""

    def start(port: int | None) -> tuple[subprocess.Popen[str], int]:
        proc = subprocess.Popen(
            [sys.executable, "-m", "tests.drivers.modbus_peer", *([str(port)] if port else [])],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert line.startswith("READY"), line
        return proc, int(line.split()[1])

    proc, port = start(None)
    try:
        laser = tcp_laser(port)
        laser.connect()
        laser.on()
        proc.kill()
        proc.wait(5)
        with pytest.raises(DeviceDisconnectedError):
            laser.off()
        proc, _ = start(port)
        laser.off()  # the driver reconnects on the next request
        assert laser.state() is False
        laser.close()
    finally:
        proc.kill()
        proc.wait(5)


def test_rtu_switch_round_trip(rtu_pair) -> None:
    _, path = rtu_pair
    with rtu_laser(path, timeout_s=ANSWER_S) as laser:
        laser.on()
        assert laser.state() is True
        laser.off()
        assert laser.state() is False


def test_rtu_server_gone_is_a_timeout_within_the_bound(rtu_pair) -> None:
    server, path = rtu_pair
    laser = rtu_laser(path, retries=1)
    laser.connect()
    server.stop()
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeoutError, match="2 attempt"):
        laser.on()
    assert time.monotonic() - t0 < 2 * 2 * TIMEOUT + 0.5
    laser.close()


def test_rtu_unknown_unit_id_is_a_clear_error(rtu_pair) -> None:
    # pymodbus 3.16's server answers an unknown unit with exception 4 (a silent unit is covered
    # by test_rtu_server_gone_is_a_timeout_within_the_bound).
    _, path = rtu_pair
    with pytest.raises(BadReplyError, match=r"exception 4 .*\[laser\]\.device_id"):
        rtu_laser(path, device_id=9, retries=0).connect()


def test_rtu_missing_port_is_device_not_found() -> None:
    with pytest.raises(DeviceNotFoundError, match="/dev/ttyNOPE"):
        rtu_laser("/dev/ttyNOPE").connect()


@pytest.mark.parametrize(
    ("settings", "key"),
    [
        ({"transport": "udp"}, "transport"),
        ({"tcp_port": 0}, "tcp_port"),
        ({"coil": -1}, "coil"),
        ({"device_id": 300}, "device_id"),
        ({"transport": "rtu"}, "serial_port"),
        ({"timeout_s": 0}, "timeout_s"),
    ],
)
def test_bad_settings_name_the_key(settings: dict[str, object], key: str) -> None:
    with pytest.raises(DeviceConfigError) as info:
        ModbusLaserConfig(**settings)  # type: ignore[arg-type]
    assert info.value.key == f"[laser].{key}"
