"""Service responsiveness: 20 clients polling `status` at 20 Hz while a long command runs.

The service runs in its own process (as under systemd) with a job in progress; each client
has its own connection and sends `status` every 50 ms on a fixed schedule. A reply that is
missing (1 s timeout), late or an error counts as missed. Reported: missed replies, median,
p99 and max round-trip latency.

Devices: until the simulated cell and the sorting pipeline exist, the service runs on the
in-memory test devices of tests/service/fakes.py and the long command is a `move` whose
in-memory arm takes the whole measurement window; the figures say so in `devices`.
"""

from __future__ import annotations

import signal
import statistics
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

CLIENTS = 20
RATE_HZ = 20.0
DURATION_S = 5.0
REPLY_TIMEOUT_S = 1.0


def _poll(host: str, port: int, stop_at: float, latencies: list[float], missed: list[str]) -> None:
    from omnisort_hw.service.client import Client, ClientError

    period = 1.0 / RATE_HZ
    try:
        client = Client(host, port, timeout_s=REPLY_TIMEOUT_S)
    except ClientError as exc:
        missed.append(f"connect: {exc}")
        return
    with client:
        next_t = time.monotonic()
        while next_t < stop_at:
            t0 = time.perf_counter()
            try:
                reply = client.call("status")
            except ClientError as exc:
                missed.append(str(exc))
                return
            dt = time.perf_counter() - t0
            if not reply.get("ok") or reply["result"].get("job") is None:
                missed.append(f"bad reply or no job running: {str(reply)[:120]}")
            latencies.append(dt)
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))


def run(shared: Path) -> dict[str, Any]:
    from omnisort_hw.service.client import Client
    from tests.service.procs import start_service

    with tempfile.TemporaryDirectory() as tmp:
        proc, host, port = start_service(Path(tmp), "--move-seconds", str(DURATION_S + 3.0))
        try:
            with Client(host, port, timeout_s=30) as mover:
                mover.send("move", {"joints_deg": [30, 0, 0, 0, 0, 0]})
                for _ in range(200):
                    if mover.call("status")["result"]["state"] == "moving":
                        break
                    time.sleep(0.01)
                latencies: list[float] = []
                missed: list[str] = []
                stop_at = time.monotonic() + DURATION_S
                threads = [
                    threading.Thread(target=_poll, args=(host, port, stop_at, latencies, missed))
                    for _ in range(CLIENTS)
                ]
                for t in threads:
                    t.start()
                for t in threads:
                    t.join(DURATION_S + 30)
                state_after = mover.call("status")["result"]["state"]
                move_reply = mover.read_reply(timeout_s=30)
        finally:
            proc.send_signal(signal.SIGTERM)
            try:
                rc = proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                rc = None
    lat_ms = sorted(x * 1000 for x in latencies)
    expected = int(CLIENTS * RATE_HZ * DURATION_S)
    return {
        "devices": "in-memory test devices (simulated cell not available yet)",
        "long_command": f"move on the in-memory arm ({DURATION_S + 3.0:g} s)",
        "clients": CLIENTS,
        "rate_hz_per_client": RATE_HZ,
        "duration_s": DURATION_S,
        "status_requests": len(latencies),
        "status_expected_approx": expected,
        "missed_replies": len(missed),
        "missed_examples": missed[:3],
        "latency_median_ms": round(statistics.median(lat_ms), 3) if lat_ms else None,
        "latency_p99_ms": round(lat_ms[int(0.99 * (len(lat_ms) - 1))], 3) if lat_ms else None,
        "latency_max_ms": round(lat_ms[-1], 3) if lat_ms else None,
        "job_state_during_polling": state_after,
        "long_command_reply_ok": bool(move_reply.get("ok")),
        "service_exit_code_after_sigterm": rc,
    }
