"""The drift watchdog: `omnisort evaluate drift` at its defaults (2 scenes, clean and degraded
camera, 200 unmoved captures, bumps of 0.05/0.1/0.3/1 deg about X, Y, Z of S, both signs,
960 px), and what one check and one PLC register read cost on this machine.

OMNISORT_BENCH_DRIFT_UNMOVED shrinks the unmoved captures for a quick run (the record is made
with the default, 200)."""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.evaluation.drift import evaluate_drift

SEED = 17
UNMOVED = int(os.environ.get("OMNISORT_BENCH_DRIFT_UNMOVED", "200"))


def figures(res: dict[str, Any]) -> dict[str, Any]:
    """The record's keys from an `evaluate_drift` result."""
    out: dict[str, Any] = {
        "seed": res["seed"],
        "width_px": res["width"],
        "scenes": res["scenes"],
        "unmoved_captures": res["unmoved_captures"],
        "occluded_captures": res["occluded_captures"],
        "false_alarms": res["false_alarms"],
        "max_unmoved_angle_deg": res["max_unmoved_angle_deg"],
        "threshold_deg_median": res["threshold_deg_median"],
        "threshold_deg_max": res["threshold_deg_max"],
        "seconds": res["seconds"],
    }
    for size, row in res["bumps"].items():
        for key in ("captures", "detected", "max_angle_error_deg"):
            out[f"bump_{size}_{key}"] = row[key]
    return out


def _plc_read_ms(n: int = 300) -> tuple[float, float]:
    """Median and p99 of one 11-register read from a pymodbus client (in-memory cell)."""
    from pymodbus.client import ModbusTcpClient

    from omnisort_hw.config.service import ServiceConfig
    from omnisort_hw.config.watchdog import PlcConfig
    from omnisort_hw.service.plc_face import REGISTERS, PlcFace
    from omnisort_hw.service.server import Service, start_in_thread
    from tests.service.fakes import make_cell

    with tempfile.TemporaryDirectory() as tmp:
        cell, _, _ = make_cell(Path(tmp) / "state", Path(tmp) / "logs")
        running = start_in_thread(Service(cell, ServiceConfig(port=0)))
        face = PlcFace(running.service, PlcConfig(modbus_port=0))
        host, port = face.start()
        client = ModbusTcpClient(host, port=port, timeout=5)
        client.connect()
        times = []
        try:
            for _ in range(n):
                t0 = time.perf_counter()
                r = client.read_input_registers(0, count=len(REGISTERS), device_id=1)
                times.append(time.perf_counter() - t0)
                assert not r.isError()
        finally:
            client.close()
            face.close()
            running.stop()
    ms = np.asarray(times) * 1e3
    return float(np.median(ms)), float(np.percentile(ms, 99))


def run(shared: Path) -> dict[str, Any]:
    del shared
    res = evaluate_drift(seed=SEED, scenes=2, unmoved=UNMOVED, width=960)
    out = figures(res)
    checks = res["unmoved_captures"] + sum(r["captures"] for r in res["bumps"].values())
    out["seconds_per_check_with_render"] = round(res["seconds"] / max(1, checks), 2)
    med, p99 = _plc_read_ms()
    out["plc_read_ms_median"] = round(med, 2)
    out["plc_read_ms_p99"] = round(p99, 2)
    return out
