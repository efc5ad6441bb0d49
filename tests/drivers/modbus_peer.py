"""Real pymodbus servers for the Modbus laser tests: TCP on 127.0.0.1 and RTU over a pty pair.

`ModbusTestServer` runs a pymodbus 3.x server (`ModbusTcpServer` or `ModbusSerialServer`) on its
own asyncio loop in a background thread; `stop()` shuts it down, which closes the listening
socket and every client connection ("the server goes away"). The device has coils 0..31; any
other coil address gets the exception response ILLEGAL DATA ADDRESS.

`PtyBridge` joins two pseudo-terminals back to back like a null-modem cable (socat is not
needed): the RTU server opens one slave, the driver the other.

Run as a script (`python -m tests.drivers.modbus_peer`) it serves Modbus TCP in a separate
process and prints `READY <port>`; the tests kill that process to pull the plug for real.
"""

from __future__ import annotations

import asyncio
import os
import select
import socket
import sys
import threading
import tty

from pymodbus.server import ModbusSerialServer, ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

N_COILS = 32


def free_tcp_port() -> int:
    """An ephemeral port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def laser_device(device_id: int = 1) -> SimDevice:
    """One unit with coils 0..31 (bit-addressed), all off."""
    return SimDevice(
        device_id,
        simdata=[SimData(0, values=[0] * (N_COILS // 16), datatype=DataType.REGISTERS)],
        use_bit_addressing=True,
    )


class ModbusTestServer:
    """A pymodbus server in a background thread; TCP when `serial_port` is None, else RTU."""

    def __init__(
        self, *, port: int | None = None, serial_port: str | None = None, device_id: int = 1
    ) -> None:
        self.port = port if port is not None else free_tcp_port()
        self.serial_port = serial_port
        self.device_id = device_id
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._server: ModbusTcpServer | ModbusSerialServer | None = None
        self._thread = threading.Thread(target=self._run, name="modbus-test-server", daemon=True)
        self._thread.start()
        if not self._ready.wait(5.0):
            raise RuntimeError("pymodbus test server did not start within 5 s")
        if self._error is not None:
            raise RuntimeError(f"pymodbus test server failed: {self._error}")

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)

        async def main() -> None:
            try:
                device = laser_device(self.device_id)
                if self.serial_port is None:
                    self._server = ModbusTcpServer(device, address=("127.0.0.1", self.port))
                else:
                    self._server = ModbusSerialServer(
                        device,
                        port=self.serial_port,
                        baudrate=115200,
                        timeout=0.05,
                    )
                await self._server.serve_forever(background=True)
            except BaseException as exc:
                self._error = exc
                self._ready.set()
                return
            self._ready.set()
            await self._server.serving

        self._loop.run_until_complete(main())

    def stop(self) -> None:
        """Shut the server down (closes the listener and all connections)."""
        if self._server is not None and self._thread.is_alive():
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
            fut.result(5.0)
        self._thread.join(5.0)

    def __enter__(self) -> ModbusTestServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class PtyBridge:
    """Two ptys joined back to back; `a` and `b` are the slave paths to open."""

    def __init__(self) -> None:
        self._m1, self._s1 = os.openpty()
        self._m2, self._s2 = os.openpty()
        for fd in (self._s1, self._s2):
            tty.setraw(fd)
        self.a = os.ttyname(self._s1)
        self.b = os.ttyname(self._s2)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pty-bridge", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        peers = {self._m1: self._m2, self._m2: self._m1}
        try:
            while not self._stop.is_set():
                readable, _, _ = select.select(list(peers), [], [], 0.02)
                for fd in readable:
                    try:
                        data = os.read(fd, 4096)
                    except OSError:
                        continue
                    if data:
                        os.write(peers[fd], data)
        finally:
            for fd in (self._m1, self._m2, self._s1, self._s2):
                os.close(fd)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


def main() -> int:
    port = int(sys.argv[1]) if len(sys.argv) > 1 else free_tcp_port()
    server = ModbusTestServer(port=port)
    print(f"READY {server.port}", flush=True)
    try:
        threading.Event().wait()
    finally:
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
