"""The laser switch as a Modbus TCP I/O module (pymodbus 3.x server on its own asyncio loop).

The unit has coils 0..15; the laser is coil `coil`. Writing it switches the simulated laser,
reading any coil returns the module's state (the laser coil reads the world's laser). Any
other address gets the exception reply ILLEGAL DATA ADDRESS from pymodbus itself. A stall
(control channel) delays every reply by its remaining time, like a module that stops answering.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

MODBUS_PORT = 5020  # 502 needs root; the cell file names the port
N_COILS = 16


class LaserModbusServer:
    """Modbus TCP on host:port whose coil `coil` is the simulated laser's switch."""

    def __init__(
        self,
        host: str,
        cell: Any,
        faults: Any,
        port: int = MODBUS_PORT,
        coil: int = 0,
        device_id: int = 1,
    ) -> None:
        self.host, self.port, self.coil, self.device_id = host, port, coil, device_id
        self.cell = cell
        self.faults = faults
        self.requests = 0
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._server: ModbusTcpServer | None = None
        self._thread = threading.Thread(target=self._run, name="laser-modbus", daemon=True)

    async def _action(
        self,
        function_code: int,
        start_address: int,
        address: int,
        count: int,
        current_registers: list[int],
        set_values: list[int] | list[bool] | None,
    ) -> None:
        self.requests += 1
        while self.faults.stalled("laser"):
            await asyncio.sleep(0.01)
        world = self.cell.world
        first = address
        if set_values is not None and first <= self.coil < first + len(set_values):
            with self.cell.lock:
                world.laser_on = bool(set_values[self.coil - first])
        bit = self.coil - start_address * 16
        if 0 <= bit < 16 * len(current_registers):
            reg, off = divmod(bit, 16)
            value = current_registers[reg] & ~(1 << off)
            current_registers[reg] = value | (int(bool(world.laser_on)) << off)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)

        async def main() -> None:
            try:
                device = SimDevice(
                    self.device_id,
                    simdata=[SimData(0, values=[0] * (N_COILS // 16), datatype=DataType.REGISTERS)],
                    use_bit_addressing=True,
                    action=self._action,
                )
                self._server = ModbusTcpServer(device, address=(self.host, self.port))
                await self._server.serve_forever(background=True)
            except BaseException as exc:
                self._error = exc
                self._ready.set()
                return
            self._ready.set()
            await self._server.serving

        self._loop.run_until_complete(main())

    def start(self, timeout_s: float = 5.0) -> None:
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise RuntimeError(f"Modbus server on {self.host}:{self.port} did not start")
        if self._error is not None:
            raise RuntimeError(f"Modbus server on {self.host}:{self.port}: {self._error}")

    def drop(self) -> None:
        """Close every client connection (the server keeps listening)."""
        server = self._server
        if server is None:
            return

        async def close_all() -> None:
            for conn in list(getattr(server, "active_connections", {}).values()):
                conn.close()

        asyncio.run_coroutine_threadsafe(close_all(), self._loop).result(2.0)

    def close(self) -> None:
        if self._server is not None and self._thread.is_alive():
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
            fut.result(5.0)
        self._thread.join(5.0)
