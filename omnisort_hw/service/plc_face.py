"""The service's PLC face: a Modbus TCP server (pymodbus) beside the JSON protocol.

Input registers (function 4) give the cell's state, job progress, counts, last error, the
calibration's health and drift and a heartbeat; coils (functions 1, 5, 15) start a sort, stop
and reset. A coil command is turned into the same request the JSON protocol would carry and
handed to the service's own dispatcher on its event loop, so the state machine and every rule
(busy, fault, calibration, drift) apply unchanged. Register map: docs/plc.md (`REGISTERS`,
`COILS` here are its source).

Modbus has no authentication: coil writes are refused (exception ILLEGAL FUNCTION) unless
`[plc] allow_commands = true`. Every request that does not fit the map gets an exception
reply (ILLEGAL DATA ADDRESS / VALUE, DEVICE BUSY, DEVICE FAILURE) and nothing else happens.
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Sequence
from typing import Any, Protocol

from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.server import ModbusTcpServer

from omnisort_hw.config.watchdog import PlcConfig
from omnisort_hw.errors import ConfigError
from omnisort_hw.service import protocol as proto
from omnisort_hw.service.status_reading import pick_log, sort_progress

log = logging.getLogger("omnisort.plc")

STATES = ("idle", "calibrating", "mapping", "sorting", "moving", "stopped", "fault")
# Input registers, address -> (name, meaning); docs/plc.md is written from this table.
REGISTERS: tuple[tuple[str, str], ...] = (
    ("state", "0 idle, 1 calibrating, 2 mapping, 3 sorting, 4 moving, 5 stopped, 6 fault"),
    ("progress_done", "cubes finished (sorted, skipped or failed) by the current/last sort"),
    ("progress_total", "cubes the current/last sort planned to pick (0 before planning)"),
    ("sorted", "cubes sorted by the current/last sort"),
    ("skipped", "cubes skipped by the current/last sort"),
    ("failed", "cubes failed by the current/last sort"),
    ("last_error", "code of the last error (table in docs/plc.md), 0 = none"),
    (
        "calibration_bits",
        "bit 0 camera.json ok, 1 system.json ok, 2 robot registered, "
        "3 motion allowed, 4 drift refuses motion, 5 drift acknowledged, 6 last check ran",
    ),
    ("drift_mdeg", "camera turn found by the last drift check, milli-degrees (0..65535)"),
    ("heartbeat", "seconds since the PLC face started, modulo 65536: changes every second"),
    ("commands_enabled", "1 when [plc] allow_commands = true"),
)
COILS = ("start_sort", "stop", "reset")
COMMAND_OF = {0: "sort", 1: "stop", 2: "reset"}
START_WAIT_S = 1.0  # how long a coil write waits for the job to be accepted or refused
REFRESH_S = 0.2


def error_number(code: str | None) -> int:
    """The register value of a protocol error code (1-based index, 0 = none)."""
    if not code:
        return 0
    codes = proto.ERROR_CODES
    return codes.index(code) + 1 if code in codes else len(codes) + 1


class _Context(ModbusServerContext):
    """The map as pymodbus sees it: every read and write goes through the face."""

    def __init__(self, face: PlcFace) -> None:  # no super(): its data blocks are not used
        self.face = face
        self.old_simulator = True
        self.simdevices = []
        self._devices = {}

    def device_ids(self) -> list[int]:
        return [1]  # every unit id is answered (one cell per server)

    async def async_getValues(
        self, device_id: int, func_code: int, address: int, count: int = 1
    ) -> list[int] | list[bool] | ExcCodes:
        return self.face.read(func_code, address, count)

    async def async_setValues(
        self, device_id: int, func_code: int, address: int, values: Sequence[int] | Sequence[bool]
    ) -> ExcCodes | None:
        return await asyncio.to_thread(self.face.write, func_code, address, list(values))


class PlcPort(Protocol):
    """What the PLC face needs of its service (`server.Service` is one): the `status` reply
    and a command handed to its dispatcher from this thread."""

    def status_reply(self) -> dict[str, Any]: ...

    def call_from_thread(self, cmd: str, wait_s: float) -> dict[str, Any] | None:
        """The reply to `cmd`, or None when it still runs after `wait_s` (a job)."""
        ...


class PlcFace:
    """The Modbus TCP server of one service, on its own thread and event loop."""

    def __init__(self, service: PlcPort, config: PlcConfig) -> None:
        if config.modbus_port is None:
            raise ConfigError("[plc] modbus_port is not set")
        if config.allow_commands and not config.on_loopback:
            log.warning(
                "PLC commands enabled on %s: Modbus has no authentication, keep this port on "
                "the line's own network",
                config.host,
            )
        self.service = service
        self.config = config
        self.address: tuple[str, int] | None = None
        self._regs = [0] * len(REGISTERS)
        self._last_error = 0
        self._seen_end: str | None = None
        self._started = time.monotonic()
        self._lock = threading.Lock()
        self._loop = asyncio.new_event_loop()
        self._server: ModbusTcpServer | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="plc-modbus", daemon=True)
        self.requests = 0
        self.exceptions = 0

    # -- registers ---------------------------------------------------------------------------

    def snapshot(self) -> list[int]:
        """The input registers now (from the service's status snapshot: no device call)."""
        st = self.service.status_reply()
        state = STATES.index(st["state"]) if st["state"] in STATES else 0xFFFF
        run = st.get("last_run") or {}
        picks = pick_log(dict(st))
        counts = {k: sum(p.outcome == k for p in picks) for k in ("sorted", "skipped", "failed")}
        done = sum(counts.values())
        total = (sort_progress(dict(st)) or (0, 0))[1]
        ended = run.get("ended")
        if ended and ended != self._seen_end:
            self._seen_end = ended
            if run.get("state") in ("failed", "stopped", "interrupted"):
                self._last_error = error_number(str(run.get("outcome") or "").split(":", 1)[0])
        cal = st.get("calibration") or {}
        files = cal.get("files") or {}
        drift = st.get("drift") or {}
        last = drift.get("last") or {}
        bits = (
            int((files.get("camera") or {}).get("health") == "ok")
            | int((files.get("system") or {}).get("health") == "ok") << 1
            | int(bool(cal.get("robot_registered"))) << 2
            | int(bool(st.get("motion_allowed"))) << 3
            | int(bool(drift.get("motion_refused"))) << 4
            | int(bool(drift.get("acknowledged"))) << 5
            | int(bool(last)) << 6
        )
        mdeg = round(1000.0 * float(last.get("angle_deg") or 0.0))
        heartbeat = int(time.monotonic() - self._started) & 0xFFFF
        return [
            state,
            done,
            total,
            counts["sorted"],
            counts["skipped"],
            counts["failed"],
            self._last_error,
            bits,
            max(0, min(mdeg, 0xFFFF)),
            heartbeat,
            int(self.config.allow_commands),
        ]

    def refresh(self) -> None:
        regs = self.snapshot()
        with self._lock:
            self._regs = regs

    # -- requests ----------------------------------------------------------------------------

    def read(self, func_code: int, address: int, count: int) -> list[int] | list[bool] | ExcCodes:
        self.requests += 1
        if func_code == 4:
            size = len(REGISTERS)
            if address < 0 or count < 1 or address + count > size:
                return self._exc(ExcCodes.ILLEGAL_ADDRESS)
            with self._lock:
                return list(self._regs[address : address + count])
        if func_code in (1, 5, 15):  # 5 and 15: pymodbus reads the coils back after a write
            if address < 0 or count < 1 or address + count > len(COILS):
                return self._exc(ExcCodes.ILLEGAL_ADDRESS)
            with self._lock:
                sorting = self._regs[0] == STATES.index("sorting")
                stopped = self._regs[0] == STATES.index("stopped")
            coils = [sorting, stopped, False]
            return coils[address : address + count]
        # Discrete inputs, holding registers: not in the map.
        return self._exc(ExcCodes.ILLEGAL_ADDRESS)

    def write(self, func_code: int, address: int, values: list[Any]) -> ExcCodes | None:
        self.requests += 1
        if func_code not in (5, 15):
            return self._exc(ExcCodes.ILLEGAL_ADDRESS)  # no writable registers
        if address < 0 or address + len(values) > len(COILS) or not values:
            return self._exc(ExcCodes.ILLEGAL_ADDRESS)
        if not self.config.allow_commands:
            return self._exc(ExcCodes.ILLEGAL_FUNCTION)
        set_coils = [address + i for i, v in enumerate(values) if v]
        if len(set_coils) > 1:
            return self._exc(ExcCodes.ILLEGAL_VALUE)  # one command per write
        if not set_coils:
            return None  # writing 0 to a command coil does nothing
        return self._command(COMMAND_OF[set_coils[0]])

    def _exc(self, code: ExcCodes) -> ExcCodes:
        self.exceptions += 1
        return code

    def _command(self, cmd: str) -> ExcCodes | None:
        """Hand `cmd` to the service's dispatcher like a JSON request; a job that is still
        running after START_WAIT_S was accepted."""
        log.info("PLC command: %s", cmd)
        try:
            reply = self.service.call_from_thread(cmd, START_WAIT_S)
        except Exception as exc:
            log.warning("PLC command %s failed: %s", cmd, exc)
            return self._exc(ExcCodes.DEVICE_FAILURE)
        if reply is None:
            return None  # the job runs; its end shows in the registers
        if reply.get("ok"):
            return None
        code = reply["error"]["code"]
        self._last_error = error_number(code)
        log.warning("PLC command %s refused: %s", cmd, reply["error"]["message"])
        return self._exc(ExcCodes.DEVICE_BUSY if code == proto.BUSY else ExcCodes.DEVICE_FAILURE)

    # -- life cycle --------------------------------------------------------------------------

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)

        async def main() -> None:
            try:
                self.refresh()
                self._server = ModbusTcpServer(
                    _Context(self), address=(self.config.host, int(self.config.modbus_port or 0))
                )
                await self._server.serve_forever(background=True)
                # pymodbus annotates `transport` as BaseTransport, but a listening server's is
                # the asyncio.Server of loop.create_server (which has `sockets`)
                sock = self._server.transport.sockets[0].getsockname()  # type: ignore[attr-defined]
                self.address = (str(sock[0]), int(sock[1]))
            except BaseException as exc:
                self._error = exc
                self._ready.set()
                return
            self._ready.set()
            while not self._server.serving.done():
                try:
                    await asyncio.to_thread(self.refresh)
                except Exception as exc:
                    log.warning("PLC register refresh failed: %s", exc)
                await asyncio.sleep(REFRESH_S)

        self._loop.run_until_complete(main())

    def start(self, timeout_s: float = 5.0) -> tuple[str, int]:
        """Listen; returns the (host, port) bound (port 0 picks a free one)."""
        self._thread.start()
        if not self._ready.wait(timeout_s):
            raise ConfigError(f"[plc] Modbus server on {self.config.host} did not start")
        if self._error is not None or self.address is None:
            raise ConfigError(
                f"[plc] Modbus server on {self.config.host}:{self.config.modbus_port}: "
                f"{self._error}"
            )
        log.info("PLC face (Modbus TCP) on %s:%d", *self.address)
        return self.address

    def close(self) -> None:
        if self._server is not None and self._thread.is_alive():
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
            try:
                fut.result(5.0)
            except Exception as exc:
                log.warning("PLC face shutdown: %s", exc)
        self._thread.join(5.0)


def start_plc_face(service: PlcPort, config: PlcConfig) -> PlcFace | None:
    """The PLC face of `[plc]`, listening, or None when `modbus_port` is not set."""
    if config.modbus_port is None:
        return None
    face = PlcFace(service, config)
    face.start()
    return face
