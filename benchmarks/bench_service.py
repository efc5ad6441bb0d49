"""Service responsiveness: 20 clients polling `status` at 20 Hz while a long command runs.

`omnisort serve` runs in its own process (as under systemd; READY and the port come over a
notify socket) on a virtual cell: the simulated cell in a process of its own, driven through
the real drivers and protocols (MJPEG stream, Modbus, ur-rtde), so the service's process holds
what it holds on a real cell and no more. Measured, one after the other on the same service:
- idle: the same clients with nothing running (the reference p99, under identical load);
- `calibrate what=intrinsics` on rendered checkerboard views (the compute worker's job);
- `sort` of the scene's cubes, paced by the emulated controller's wall clock.
Then the same sort and calibrations on the simulated cell as `omnisort serve` opens it
(`backend = "sim"`): the pybullet world, its renders and the sensor's exposures run in the
service's child process (`sim_backend/device_host.py`), the service holds proxies.
Each client has its own connection, from its own loopback address (20 HMIs on the line's
network; the service limits connections per address), and sends `status` every 50 ms on a
fixed schedule. A reply that is missing (1 s timeout) or an error counts as missed. Reported
per phase: requests, missed replies, median, p99 and max round-trip latency.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

CLIENTS = 20
RATE_HZ = 20.0
REPLY_TIMEOUT_S = 1.0
WIDTH = 960


def _poll(
    port: int,
    source: str,
    stop: threading.Event,
    latencies: list[float],
    missed: list[str],
    busy: list[int],
) -> None:
    from omnisort_hw.service.client import Client, ClientError

    period = 1.0 / RATE_HZ
    try:
        client = Client("127.0.0.1", port, timeout_s=REPLY_TIMEOUT_S, source_host=source)
    except ClientError as exc:
        missed.append(f"connect: {exc}")
        return
    with client:
        next_t = time.monotonic()
        while not stop.is_set():
            t0 = time.perf_counter()
            try:
                reply = client.call("status")
            except ClientError as exc:
                missed.append(str(exc))
                return
            latencies.append(time.perf_counter() - t0)
            if not reply.get("ok"):
                missed.append(f"error reply: {str(reply)[:120]}")
            elif reply["result"].get("job") is not None:
                busy[0] += 1
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))


IDLE_S = 10.0


def _phase(port: int, cmd: str | None, args: dict[str, Any]) -> dict[str, Any]:
    """Poll status from CLIENTS threads while `cmd` runs on another connection (None: for
    IDLE_S with nothing running, the reference under the same client load)."""
    from omnisort_hw.service.client import Client

    latencies: list[float] = []
    missed: list[str] = []
    busy = [0]
    stop = threading.Event()
    threads = [
        threading.Thread(
            target=_poll, args=(port, f"127.0.1.{k + 1}", stop, latencies, missed, busy)
        )
        for k in range(CLIENTS)
    ]
    load = os.getloadavg()[0]
    with Client("127.0.0.1", port, timeout_s=600) as runner:
        for t in threads:
            t.start()
        time.sleep(0.5)
        t0 = time.monotonic()
        if cmd is None:
            time.sleep(IDLE_S)
            reply = {"ok": True}
        else:
            reply = runner.call(cmd, args)
        job_s = time.monotonic() - t0
        stop.set()
        for t in threads:
            t.join(30)
    lat_ms = sorted(x * 1000 for x in latencies)
    return {
        "long_command": f"{cmd} {args}",
        "long_command_ok": bool(reply.get("ok")),
        "long_command_s": round(job_s, 2),
        "load_avg_1min_at_start": round(load, 2),
        "status_requests": len(lat_ms),
        "status_during_job": busy[0],
        "missed_replies": len(missed),
        "missed_examples": missed[:3],
        "latency_median_ms": round(statistics.median(lat_ms), 3) if lat_ms else None,
        "latency_p99_ms": round(lat_ms[int(0.99 * (len(lat_ms) - 1))], 3) if lat_ms else None,
        "latency_max_ms": round(lat_ms[-1], 3) if lat_ms else None,
    }


def _virtual_cell_phases(tmp: Path, views: Path) -> dict[str, Any]:
    """Idle, intrinsics and sort phases on one service whose devices are a virtual cell."""
    from omnisort_hw.service.client import Client
    from omnisort_hw.service.launch import start_service
    from sim_backend.virtual_cell.cell_file import cell_file_text
    from sim_backend.virtual_cell.launcher import VirtualCellProcess

    out: dict[str, Any] = {}
    with VirtualCellProcess("sorting", width=WIDTH, unlock_delay_s=5.0) as vc:
        cfg = tmp / "cell.toml"
        cfg.write_text(cell_file_text(vc.host, state_dir="state", log_dir="logs"))
        svc = start_service(cfg, tmp)
        port = svc.port
        try:
            idle = _phase(port, None, {})
            cpu = _phase(
                port, "calibrate", {"what": "intrinsics", "folder": str(views), "square_mm": 116}
            )
            with Client("127.0.0.1", port, timeout_s=300) as c:
                prep = [
                    c.call("calibrate", {"what": "extrinsics", "target": "two-sided"}),
                    c.call("register_robot"),
                ]
            failed = [r["error"]["message"][:160] for r in prep if not r.get("ok")]
            sort = _phase(port, "sort", {}) if not failed else {"skipped": failed}
        finally:
            out["service_exit_code_after_sigterm"] = svc.stop()
    kept = ("status", "missed", "lat", "load")
    out.update({f"idle.{k}": v for k, v in idle.items() if k.startswith(kept)})
    out.update({f"during_intrinsics.{k}": v for k, v in cpu.items()})
    out.update({f"during_sort.{k}": v for k, v in sort.items()})
    return out


def _sim_host_phases(tmp: Path, views: Path) -> dict[str, Any]:
    """Sort, then intrinsics and extrinsics calibrations, on the simulated cell as the service
    opens it (`backend = "sim"`: the world in the service's child process; calibration from
    the sim's truth, so the sort can start at once)."""
    from omnisort_hw.service.demo import calibrate_from_truth, write_config
    from omnisort_hw.service.launch import start_service

    tmp.mkdir()
    cfg = write_config(tmp, WIDTH)
    calibrate_from_truth(cfg)
    svc = start_service(cfg, tmp)
    phases: dict[str, dict[str, Any]] = {}
    try:
        idle = _phase(svc.port, None, {})
        phases["sort"] = _phase(svc.port, "sort", {})
        phases["intrinsics"] = _phase(
            svc.port, "calibrate", {"what": "intrinsics", "folder": str(views), "square_mm": 116}
        )
        phases["extrinsics"] = _phase(
            svc.port, "calibrate", {"what": "extrinsics", "target": "two-sided"}
        )
    finally:
        svc.stop()
    out = {
        f"idle_sim_host.{k}": v
        for k, v in idle.items()
        if k.startswith(("status", "missed", "lat", "load"))
    }
    for name, phase in phases.items():
        phase["devices"] = f"simulated cell, backend sim ({WIDTH}x{WIDTH} camera; sim host)"
        out.update({f"during_{name}_sim_host.{k}": v for k, v in phase.items()})
    return out


def run(shared: Path) -> dict[str, Any]:
    from sim_backend.dataset import checkerboard_views

    load_before = os.getloadavg()[0]
    out: dict[str, Any] = {
        "devices": f"virtual cell (scene sorting, {WIDTH}x{WIDTH} camera; real drivers)",
        "clients": CLIENTS,
        "rate_hz_per_client": RATE_HZ,
    }
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        views = tmp / "views"
        checkerboard_views(views, n=12, seed=2, width=WIDTH, progress=False)
        out.update(_virtual_cell_phases(tmp, views))
        out.update(_sim_host_phases(tmp / "sim", views))
    out["load_avg_1min_before_after"] = [round(load_before, 2), round(os.getloadavg()[0], 2)]
    return out
