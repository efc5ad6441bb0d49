"""Laser switch on a Modbus coil (pymodbus 3.x sync client, TCP or RTU).

A switch writes the coil (function 5) and reads it back (function 1); the call returns only
when the read-back equals the request. pymodbus's own retries are switched off (`retries=0`)
so the time a call can take is bounded by this driver: at most `1 + retries` attempts of
`timeout_s` each per request. Failures become typed errors:

* nothing listening / no such serial port   -> `DeviceNotFoundError`
* connection dropped (server gone)           -> `DeviceDisconnectedError`
* no answer within `timeout_s`                -> `DeviceTimeoutError`
* Modbus exception response (bad address...)  -> `BadReplyError` naming the exception code
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from drivers._common import log, require
from drivers.base import LaserSwitch
from drivers.errors import (
    BadReplyError,
    DeviceBusyError,
    DeviceDisconnectedError,
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
)

EXCEPTION_NAMES = {
    1: "ILLEGAL FUNCTION",
    2: "ILLEGAL DATA ADDRESS",
    3: "ILLEGAL DATA VALUE",
    4: "SERVER DEVICE FAILURE",
    5: "ACKNOWLEDGE",
    6: "SERVER DEVICE BUSY",
    8: "MEMORY PARITY ERROR",
    10: "GATEWAY PATH UNAVAILABLE",
    11: "GATEWAY TARGET DEVICE FAILED TO RESPOND",
}


@dataclass(frozen=True)
class ModbusLaserConfig:
    """Settings of `[laser]` with `backend = "modbus"`.

    `transport = "tcp"` uses `host` and `tcp_port`; `"rtu"` uses `serial_port`, `baudrate`,
    `parity`, `stopbits` and `bytesize`. `device_id` is the unit/slave id; `coil` the coil
    address as sent on the wire (0-based).
    """

    SECTION: ClassVar[str] = "laser"

    transport: Literal["tcp", "rtu"] = "tcp"
    host: str = "127.0.0.1"
    tcp_port: int = 502
    serial_port: str = ""
    baudrate: int = 19200
    parity: Literal["N", "E", "O"] = "N"
    stopbits: int = 1
    bytesize: int = 8
    device_id: int = 1
    coil: int = 0
    timeout_s: float = 0.5
    retries: int = 1

    def __post_init__(self) -> None:
        s = self.SECTION
        require(self.transport in ("tcp", "rtu"), s, "transport", "must be 'tcp' or 'rtu'")
        if self.transport == "tcp":
            require(bool(self.host), s, "host", "give the IP address or host name")
            require(0 < self.tcp_port < 65536, s, "tcp_port", f"bad port {self.tcp_port}")
        else:
            require(bool(self.serial_port), s, "serial_port", "give the RS-485 adapter's device")
            require(self.baudrate > 0, s, "baudrate", f"must be positive, got {self.baudrate}")
            require(self.parity in ("N", "E", "O"), s, "parity", "must be 'N', 'E' or 'O'")
            require(self.stopbits in (1, 2), s, "stopbits", "must be 1 or 2")
            require(self.bytesize in (7, 8), s, "bytesize", "must be 7 or 8")
        require(0 <= self.device_id <= 247, s, "device_id", f"must be 0..247, got {self.device_id}")
        require(0 <= self.coil <= 65535, s, "coil", f"must be 0..65535, got {self.coil}")
        require(self.timeout_s > 0, s, "timeout_s", f"must be > 0, got {self.timeout_s}")
        require(0 <= self.retries <= 10, s, "retries", f"must be 0..10, got {self.retries}")

    @property
    def where(self) -> str:
        """Human-readable address of the device."""
        if self.transport == "tcp":
            return f"{self.host}:{self.tcp_port}"
        return self.serial_port


class ModbusLaser(LaserSwitch):
    """A laser switch driven by one Modbus coil. Thread-safe: one request at a time."""

    def __init__(self, config: ModbusLaserConfig) -> None:
        self.config = config
        self._client: ModbusTcpClient | ModbusSerialClient | None = None
        self._lock = threading.RLock()

    @property
    def name(self) -> str:
        cfg = self.config
        return (
            f"Modbus {cfg.transport.upper()} laser switch at {cfg.where} "
            f"(unit {cfg.device_id}, coil {cfg.coil})"
        )

    @property
    def is_connected(self) -> bool:
        return self._client is not None and bool(self._client.connected)

    def _make_client(self) -> ModbusTcpClient | ModbusSerialClient:
        cfg = self.config
        if cfg.transport == "tcp":
            return ModbusTcpClient(
                cfg.host,
                port=cfg.tcp_port,
                timeout=cfg.timeout_s,
                retries=0,
                reconnect_delay=0,
                name="omnisort-laser",
            )
        return ModbusSerialClient(
            cfg.serial_port,
            baudrate=cfg.baudrate,
            parity=cfg.parity,
            stopbits=cfg.stopbits,
            bytesize=cfg.bytesize,
            timeout=cfg.timeout_s,
            retries=0,
            reconnect_delay=0,
            name="omnisort-laser",
        )

    def connect(self) -> None:
        """Open the connection and read the coil once (proves the unit and address answer)."""
        with self._lock:
            if self.is_connected:
                return
            cfg = self.config
            if cfg.transport == "rtu" and not os.path.exists(cfg.serial_port):
                raise DeviceNotFoundError(
                    f"serial port {cfg.serial_port} for the Modbus RTU laser switch does not "
                    "exist: is the RS-485 adapter plugged in? (`omnisort devices list`)",
                    device=cfg.serial_port,
                )
            client = self._make_client()
            if not client.connect():
                client.close()
                raise self._not_found()
            self._client = client
            try:
                self.state()
            except DeviceError:
                self.close()
                raise

    def close(self) -> None:
        with self._lock:
            client, self._client = self._client, None
            if client is not None:
                client.close()

    def _not_found(self) -> DeviceError:
        cfg = self.config
        if cfg.transport == "tcp":
            return DeviceNotFoundError(
                f"nothing answers Modbus TCP at {cfg.where}: check [laser].host and "
                "[laser].tcp_port, the cable and that the I/O module is powered",
                device=cfg.where,
            )
        return DeviceBusyError(
            f"cannot open {cfg.serial_port} for Modbus RTU: in use by another process or no "
            "permission (`fuser`, group 'dialout')",
            device=cfg.where,
        )

    def _request(self, what: str, call: Callable[[Any], Any]) -> Any:
        """One request with typed errors; `call(client)` returns the pymodbus response."""
        cfg = self.config
        if self._client is None:
            raise DeviceDisconnectedError(
                f"{self.name} is not connected: call connect() first", device=cfg.where
            )
        client = self._client
        try:
            response = call(client)
        except ModbusIOException as exc:
            raise DeviceTimeoutError(
                f"{self.name} did not answer {what} within {cfg.timeout_s:.2f} s: check "
                "[laser].device_id, the bus wiring and termination (RTU) or the network",
                device=cfg.where,
            ) from exc
        except ConnectionException as exc:
            client.close()
            raise DeviceDisconnectedError(
                f"{self.name}: connection lost during {what} (server gone or cable pulled): {exc}",
                device=cfg.where,
            ) from exc
        except ModbusException as exc:
            raise BadReplyError(
                f"{self.name}: bad reply to {what}: {exc}", device=cfg.where
            ) from exc
        except OSError as exc:
            client.close()
            raise DeviceDisconnectedError(
                f"{self.name}: I/O error during {what}: {exc}", device=cfg.where
            ) from exc
        if response.isError():
            code = int(getattr(response, "exception_code", 0))
            hint = {
                2: ": check [laser].coil",
                3: ": check [laser].coil",
                4: ": check [laser].device_id and the I/O module",
                11: ": check [laser].device_id and the gateway's serial side",
            }.get(code, ": check the I/O module")
            raise BadReplyError(
                f"{self.name} refused {what}: Modbus exception {code} "
                f"({EXCEPTION_NAMES.get(code, 'unknown')}){hint}",
                device=cfg.where,
            )
        return response

    def _with_retries(self, what: str, timeout_s: float | None, fn: Callable[[], bool]) -> bool:
        budget = (
            timeout_s
            if timeout_s is not None
            else (self.config.retries + 1) * 2 * self.config.timeout_s
        )
        deadline = time.monotonic() + budget
        last: DeviceTimeoutError | None = None
        tries = 0
        while tries <= self.config.retries and time.monotonic() < deadline:
            tries += 1
            try:
                return fn()
            except DeviceTimeoutError as exc:
                last = exc
                log.warning("%s: %s attempt %d timed out", self.name, what, tries)
        raise DeviceTimeoutError(
            f"{last or self.name + ' timed out'} [{what}: {tries} attempt(s)]",
            device=self.config.where,
        ) from last

    def _read(self) -> bool:
        cfg = self.config
        rr = self._request(
            f"read coil {cfg.coil}",
            lambda c: c.read_coils(cfg.coil, count=1, device_id=cfg.device_id),
        )
        if not getattr(rr, "bits", None):
            raise BadReplyError(
                f"{self.name}: read of coil {cfg.coil} returned no bits", device=cfg.where
            )
        return bool(rr.bits[0])

    def state(self, timeout_s: float | None = None) -> bool:
        """Read the coil (True = laser on)."""
        with self._lock:
            return self._with_retries("read", timeout_s, self._read)

    def set(self, on: bool, timeout_s: float | None = None) -> None:
        """Write the coil, then read it back; raise if it does not read back as written."""
        cfg = self.config

        def attempt() -> bool:
            self._request(
                f"write coil {cfg.coil} = {int(on)}",
                lambda c: c.write_coil(cfg.coil, on, device_id=cfg.device_id),
            )
            actual = self._read()
            if actual != on:
                raise BadReplyError(
                    f"{self.name}: coil {cfg.coil} reads back {int(actual)} after writing "
                    f"{int(on)} (another master or the module's logic overrides it?)",
                    device=cfg.where,
                )
            return actual

        with self._lock:
            self._with_retries(f"switch {'on' if on else 'off'}", timeout_s, attempt)
