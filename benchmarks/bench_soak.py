"""Soak: `omnisort serve` on the simulated cell under steady work and periodic abuse for
SOAK_S seconds (env OMNISORT_SOAK_S, default 600: the README figure).

Work: one `sort` first, then back-to-back jobs (joint `move`s, `locate`), `capture`s and
laser switching on one connection; 5 clients poll `status` at 20 Hz. Abuse every 30 s, in
turn: 100 idle connections held for 3 s, a never-reading client sending 20,000 requests, a
storm of 200 connects, a line without a newline. The run log is given small limits (5 MB a
file, 30 MB in all) so rolling happens during jobs.

Reported: requests and errors (any reply that is not ok, any missing reply), RSS at the start
of the steady phase and at the end and its drift (median of the last tenth against median of
the second tenth, so start-up allocation is excluded), open file descriptors (min/max after
warm-up), the largest `.rrd` file and the log directory's total.
"""

from __future__ import annotations

import os
import socket
import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

SOAK_S = float(os.environ.get("OMNISORT_SOAK_S", "600"))
POLLERS = 5
ABUSE_EVERY_S = 30.0
RRD_FILE_MB = 5
RRD_TOTAL_MB = 30


def _work(host: str, port: int, stop: threading.Event, counts: dict[str, Any]) -> None:
    from omnisort_hw.service.client import Client

    with Client(host, port, timeout_s=300) as c:
        first = c.call("sort")
        counts["first_sort"] = first["result"]["totals"] if first["ok"] else first["error"]
        q0 = c.call("status")["result"]["devices"]["arm"]["joints_deg"]
        q1 = [q0[0] + 15.0, *q0[1:]]
        steps = [
            ("move", {"joints_deg": q1}),
            ("locate", None),
            ("move", {"joints_deg": q0}),
            ("capture", {"laser": True}),
            ("laser", {"on": False}),
        ]
        k = 0
        while not stop.is_set():
            cmd, args = steps[k % len(steps)]
            k += 1
            try:
                reply = c.call(cmd, args)
            except Exception as exc:
                counts["errors"].append(f"{cmd}: {exc}")
                return
            counts["work"] += 1
            counts["jobs"] += cmd in ("move", "locate")
            if not reply["ok"]:
                counts["errors"].append(f"{cmd}: {reply['error']}")


def _abuse(host: str, port: int, round_: int) -> None:
    from omnisort_hw.service.loadgen import idle_connections, never_reading_flood

    kind = round_ % 4
    if kind == 0:
        with idle_connections(host, port, 100, [f"127.0.1.{i}" for i in range(1, 8)]):
            time.sleep(3.0)
    elif kind == 1:
        never_reading_flood(host, port, 20_000, hold_s=5.0)
    elif kind == 2:
        for _ in range(200):
            socket.create_connection((host, port), 5.0).close()
    else:
        with socket.create_connection((host, port), 5.0) as s:
            s.sendall(b'{"id": 1, "cmd": "sta')
            s.settimeout(30.0)
            while s.recv(65536):
                pass


def run(shared: Path) -> dict[str, Any]:
    from benchmarks.bench_faults import sim_service
    from omnisort_hw.cell.rrd import rrd_files
    from omnisort_hw.service.loadgen import StatusPoller, open_fds, rss_bytes

    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        svc = sim_service(
            tmp,
            "write_timeout_s = 2.0\nline_timeout_s = 5.0\n",
            f"rrd_max_file_mb = {RRD_FILE_MB}\nrrd_max_total_mb = {RRD_TOTAL_MB}\n",
        )
        host, port, pid = svc.host, svc.port, svc.proc.pid
        counts: dict[str, Any] = {"work": 0, "jobs": 0, "errors": []}
        samples: list[tuple[float, int, int]] = []
        rrd_max = rrd_total = 0
        stop = threading.Event()
        pollers = [StatusPoller(host, port, period_s=0.05) for _ in range(POLLERS)]
        worker = threading.Thread(target=_work, args=(host, port, stop, counts), daemon=True)
        try:
            for p in pollers:
                p.__enter__()
            worker.start()
            t0 = time.monotonic()
            next_abuse, round_ = t0 + ABUSE_EVERY_S / 2, 0
            while time.monotonic() - t0 < SOAK_S:
                samples.append((time.monotonic() - t0, rss_bytes(pid), open_fds(pid)))
                for f in rrd_files(tmp / "logs"):
                    try:
                        size = f.stat().st_size
                    except FileNotFoundError:
                        continue
                    rrd_max = max(rrd_max, size)
                rrd_total = max(rrd_total, sum(f.stat().st_size for f in rrd_files(tmp / "logs")))
                if time.monotonic() >= next_abuse:
                    _abuse(host, port, round_)
                    round_ += 1
                    next_abuse += ABUSE_EVERY_S
                time.sleep(2.0)
            stop.set()
            worker.join(300)
            for p in pollers:
                p.__exit__()
        finally:
            stop.set()
            code = svc.stop()
    n = len(samples)
    early = [s[1] for s in samples[n // 10 : max(n // 10 + 1, n // 5)]]
    late = [s[1] for s in samples[-max(1, n // 10) :]]
    fds = [s[2] for s in samples[n // 10 :]]
    status = [p.summary() for p in pollers]
    lat_max = max((s.get("max_ms", 0.0) for s in status), default=None)
    p99 = max((s.get("p99_ms", 0.0) for s in status), default=None)
    errors = counts["errors"] + [e for p in pollers for e in p.errors]
    return {
        "soak_s": SOAK_S,
        "work_requests": counts["work"],
        "jobs": counts["jobs"],
        "first_sort": counts.get("first_sort"),
        "status_requests": sum(s["requests"] for s in status),
        "status_p99_ms": p99,
        "status_max_ms": lat_max,
        "abuse_rounds": round_,
        "errors": len(errors),
        "error_examples": errors[:3],
        "rss_early_mb": round(statistics.median(early) / 1e6, 1),
        "rss_late_mb": round(statistics.median(late) / 1e6, 1),
        "rss_drift_pct": round(100.0 * (statistics.median(late) / statistics.median(early) - 1), 2),
        "rss_mb_series": [round(s[1] / 1e6, 1) for s in samples[:: max(1, n // 20)]],
        "fds_min_max": [min(fds), max(fds)],
        "rrd_largest_mb": round(rrd_max / 1e6, 2),
        "rrd_file_limit_mb": RRD_FILE_MB,
        "rrd_dir_max_mb": round(rrd_total / 1e6, 2),
        "rrd_total_limit_mb": RRD_TOTAL_MB,
        "service_exit_code": code,
    }
