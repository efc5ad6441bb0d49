"""Device driver round trips and failure detection times on this machine's loopback peers.

Serial: the laser driver against the pty emulator of tests/drivers (default protocol, 9600 baud
configured; a pty does not throttle to the baud rate, so this is the software overhead).
Modbus: a pymodbus 3.x server on 127.0.0.1 (TCP) and over a pty pair at 115200 baud (RTU).
Failure figures: how long a silent device / a server that went away takes to become a typed
error, against the configured timeout.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

N = 200


def _ms(samples: list[float]) -> tuple[float, float]:
    ordered = sorted(samples)
    p99 = ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]
    return round(statistics.median(ordered) * 1e3, 3), round(p99 * 1e3, 3)


def _timed(fn: Callable[[], Any], n: int = N) -> tuple[float, float]:
    samples = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return _ms(samples)


def _time_to_error(fn: Callable[[], Any]) -> float:
    t0 = time.perf_counter()
    try:
        fn()
    except Exception as exc:
        if not isinstance(getattr(exc, "code", None), str):
            raise
        return round(time.perf_counter() - t0, 3)
    raise RuntimeError("expected a device error")


def run(shared: Path) -> dict[str, Any]:
    from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
    from drivers.serial_laser import SerialLaser, SerialLaserConfig
    from tests.drivers.modbus_peer import ModbusTestServer, PtyBridge
    from tests.drivers.serial_emulator import SerialDeviceEmulator

    out: dict[str, Any] = {}
    with SerialDeviceEmulator() as emu, SerialLaser(SerialLaserConfig(port=emu.path)) as laser:
        out["serial_pty_query_median_ms"], out["serial_pty_query_p99_ms"] = _timed(laser.state)
        toggle = iter(range(10**9))
        out["serial_pty_switch_median_ms"], out["serial_pty_switch_p99_ms"] = _timed(
            lambda: laser.set(next(toggle) % 2 == 0)
        )
    with SerialDeviceEmulator(mode="silent") as emu:
        silent = SerialLaser(SerialLaserConfig(port=emu.path, timeout_s=0.2, retries=0))
        out["serial_silent_to_timeout_s (timeout 0.2, 0 retries)"] = _time_to_error(silent.connect)

    with ModbusTestServer() as server:
        laser = ModbusLaser(ModbusLaserConfig(tcp_port=server.port, timeout_s=0.3))
        laser.connect()
        out["modbus_tcp_read_median_ms"], out["modbus_tcp_read_p99_ms"] = _timed(laser.state)
        toggle = iter(range(10**9))
        out["modbus_tcp_switch_median_ms"], out["modbus_tcp_switch_p99_ms"] = _timed(
            lambda: laser.set(next(toggle) % 2 == 0)
        )
        server.stop()
        out["modbus_tcp_server_gone_to_error_s"] = _time_to_error(laser.on)
        laser.close()

    bridge = PtyBridge()
    try:
        with ModbusTestServer(serial_port=bridge.a) as server:
            cfg = ModbusLaserConfig(
                transport="rtu", serial_port=bridge.b, baudrate=115200, timeout_s=0.3, retries=0
            )
            with ModbusLaser(cfg) as laser:
                out["modbus_rtu_pty_read_median_ms"], out["modbus_rtu_pty_read_p99_ms"] = _timed(
                    laser.state, 100
                )
                server.stop()
                out["modbus_rtu_server_gone_to_timeout_s (timeout 0.3)"] = _time_to_error(laser.on)
    finally:
        bridge.close()
    return out
