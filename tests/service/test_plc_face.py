"""The PLC face with a real pymodbus client on loopback: the register map read while a sort
runs on the simulated cell (progress, heartbeat), start and stop through the coils when
commands are enabled, exception replies when they are not, and 1,000 random writes that only
ever get exception replies and leave the service and its state as they were."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.config.watchdog import PlcConfig
from omnisort_hw.service.client import Client
from omnisort_hw.service.plc_face import COILS, REGISTERS, STATES, PlcFace
from omnisort_hw.service.server import RunningService, Service, start_in_thread

pytest.importorskip("pymodbus")
pytestmark = pytest.mark.timeout(300)

ModbusTcpClient = pytest.importorskip("pymodbus.client").ModbusTcpClient
IR = {name: i for i, (name, _) in enumerate(REGISTERS)}


def _wait(cond: Callable[[], bool], timeout_s: float, what: str) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


class Plc:
    """A PLC: a pymodbus client on the face's loopback port."""

    def __init__(self, face: PlcFace) -> None:
        assert face.address is not None
        self.client = ModbusTcpClient(face.address[0], port=face.address[1], timeout=5)
        assert self.client.connect()

    def regs(self) -> dict[str, int]:
        r = self.client.read_input_registers(0, count=len(REGISTERS), device_id=1)
        assert not r.isError(), r
        return {name: r.registers[i] for name, i in IR.items()}


def _start(cell: object, allow: bool) -> tuple[RunningService, PlcFace, Plc]:
    running = start_in_thread(Service(cell, ServiceConfig(port=0, job_timeout_s=240)))  # type: ignore[arg-type]
    face = PlcFace(running.service, PlcConfig(modbus_port=0, allow_commands=allow))
    face.start()
    return running, face, Plc(face)


@pytest.fixture
def fake_cell(tmp_path: Path) -> Iterator[object]:
    from tests.service.fakes import make_cell

    cell, _, _ = make_cell(tmp_path / "state", tmp_path / "logs")
    yield cell


def _random_writes(plc: Plc, rng: np.random.Generator, n: int, lo_addr: int) -> list[int]:
    """n random writes (coils, registers, single and multiple); returns the exception codes."""
    codes = []
    c = plc.client
    for _ in range(n):
        kind = int(rng.integers(4))
        addr = int(rng.integers(lo_addr, 65536 if kind % 2 else 2**16 - 200))
        if kind == 0:
            r = c.write_coil(addr, True, device_id=1)
        elif kind == 1:
            r = c.write_register(addr, int(rng.integers(0, 65536)), device_id=1)
        elif kind == 2:
            vals = [True, *(bool(v) for v in rng.integers(0, 2, int(rng.integers(0, 40))))]
            r = c.write_coils(addr, vals, device_id=1)
        else:
            vals = [int(v) for v in rng.integers(0, 65536, int(rng.integers(1, 60)))]
            r = c.write_registers(min(addr, 65535 - len(vals)), vals, device_id=1)
        assert r.isError(), (kind, addr, r)
        codes.append(int(r.exception_code))
    return codes


def test_commands_are_refused_when_not_enabled_and_garbage_never_acts(fake_cell: object) -> None:
    running, face, plc = _start(fake_cell, allow=False)
    try:
        before = plc.regs()
        assert before["commands_enabled"] == 0 and STATES[before["state"]] == "idle"
        for coil in range(len(COILS)):
            r = plc.client.write_coil(coil, True, device_id=1)
            assert r.isError() and r.exception_code == 1, r  # ILLEGAL FUNCTION
        codes = _random_writes(plc, np.random.default_rng(17), 1000, 0)
        assert set(codes) <= {1, 2, 3}
        # Reads outside the map are exceptions too.
        r = plc.client.read_input_registers(len(REGISTERS), count=1, device_id=1)
        assert r.isError() and r.exception_code == 2
        r = plc.client.read_holding_registers(0, count=1, device_id=1)
        assert r.isError()
        with Client(running.host, running.port) as c:
            st = c.call("status")["result"]
        assert st["state"] == "idle" and st["job"] is None
        assert STATES[plc.regs()["state"]] == "idle"
        assert face._thread.is_alive()
    finally:
        plc.client.close()
        face.close()
        running.stop()


def test_enabled_face_still_answers_out_of_map_writes_with_exceptions(fake_cell: object) -> None:
    running, face, plc = _start(fake_cell, allow=True)
    try:
        codes = _random_writes(plc, np.random.default_rng(3), 300, len(COILS))
        assert set(codes) <= {2, 3}
        r = plc.client.write_coils(0, [True, True, False], device_id=1)  # two commands at once
        assert r.isError() and r.exception_code == 3
        assert STATES[plc.regs()["state"]] == "idle"
    finally:
        plc.client.close()
        face.close()
        running.stop()


@pytest.mark.slow
def test_plc_reads_a_running_sort_and_starts_and_stops_it(tmp_path: Path) -> None:
    pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
    from tests.service.sim_cell import calibrated_sim_cell

    # The arm paced to the wall clock: a pick takes seconds, so the sort still runs when the
    # PLC reads it, starts a second one and stops it (unpaced, four picks take under a second).
    cell = calibrated_sim_cell(tmp_path, realtime=True)
    running, face, plc = _start(cell, allow=True)
    try:
        first = plc.regs()
        assert STATES[first["state"]] == "idle" and first["commands_enabled"] == 1
        assert first["calibration_bits"] & 0b1111 == 0b1111  # files ok, registered, may move
        _wait(lambda: plc.regs()["heartbeat"] != first["heartbeat"], 3.0, "the heartbeat")

        assert not plc.client.write_coil(0, True, device_id=1).isError()  # start sort
        seen: list[dict[str, int]] = []

        def progressed() -> bool:
            seen.append(plc.regs())
            return seen[-1]["progress_done"] >= 1

        _wait(progressed, 180.0, "a cube done")
        now = seen[-1]
        assert STATES[now["state"]] == "sorting"
        assert now["progress_total"] >= 2 and now["sorted"] >= 1
        # The heartbeat goes on during the sort (it ticks each second).
        _wait(
            lambda: (
                (r := plc.regs())["heartbeat"] != seen[0]["heartbeat"]
                and STATES[r["state"]] == "sorting"
            ),
            10.0,
            "the heartbeat during the sort",
        )
        # A second start while it runs is refused by the state machine: DEVICE BUSY.
        busy = plc.client.write_coil(0, True, device_id=1)
        assert busy.isError() and busy.exception_code == 6
        assert not plc.client.write_coil(1, True, device_id=1).isError()  # stop
        _wait(lambda: STATES[plc.regs()["state"]] == "stopped", 30.0, "the stopped state")
        with Client(running.host, running.port) as c:
            _wait(lambda: c.call("status")["result"]["job"] is None, 30.0, "the job's end")
        after = plc.regs()
        assert after["progress_done"] < after["progress_total"]
        assert after["last_error"] != 0  # the sort ended as `stopped`
        assert not plc.client.write_coil(2, True, device_id=1).isError()  # reset
        _wait(lambda: STATES[plc.regs()["state"]] == "idle", 10.0, "idle after reset")
    finally:
        plc.client.close()
        face.close()
        running.stop()


def test_the_documented_error_numbers_are_the_faces() -> None:
    """docs/plc.md's table of `last_error` values is what the face writes, code for code."""
    import re

    from omnisort_hw.service import protocol as proto
    from omnisort_hw.service.plc_face import error_number

    doc = (Path(__file__).resolve().parents[2] / "docs" / "plc.md").read_text()
    table = {code: int(n) for n, code in re.findall(r"^\| (\d+) \| `(\w+)` \|$", doc, re.M)}
    assert table == {code: error_number(code) for code in proto.ERROR_CODES}
