"""The service under faults: `stop`/`estop` latency with idle connections and with every
client slot held, and memory and others' `status` latency under a client that never reads.

`omnisort serve` runs in its own process on the simulated cell (default limits: 64 clients,
16 per address), as under systemd. Figures:
- estop round trip (connect, send, reply) on a fresh connection: unloaded, with 200 idle
  connections held (spread over 13 loopback addresses: 64 are clients, 136 wait as overflow),
  and with all 64 client slots held; each TRIALS times (estop, then reset);
- a never-reading client sending 100,000 pipelined `status` requests while another client
  polls `status` every 20 ms: the service's RSS growth and the poller's latencies.
"""

from __future__ import annotations

import statistics
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

TRIALS = 20
IDLE = 200
FLOOD = 100_000
WIDTH = 320


def sim_service(tmp: Path, service: str = "", logging: str = "") -> Any:
    """`omnisort serve` on the simulated cell, calibrated from the truth; extra TOML lines for
    [service] and [logging]."""
    from omnisort_hw.service.demo import calibrate_from_truth, write_config
    from omnisort_hw.service.launch import start_service

    config = write_config(tmp, WIDTH)
    text = config.read_text().replace('log_dir = "logs"\n', f'log_dir = "logs"\n{logging}')
    config.write_text(text + f"[service]\n{service}")
    calibrate_from_truth(config)
    # The environment of deploy/omnisort.service.
    return start_service(config, tmp / "run", extra_env={"MALLOC_ARENA_MAX": "2"})


def _estops(ctl: Any, host: str, port: int, source: str = "127.0.0.1") -> dict[str, Any]:
    """TRIALS estops on fresh connections from `source`, each followed by a reset on `ctl`
    (a connection opened before the load, so it holds a client slot)."""
    from omnisort_hw.service.loadgen import round_trip

    times, failures = [], 0
    for _ in range(TRIALS):
        reply, dt = round_trip(host, port, "estop", source)
        failures += not reply.get("ok")
        times.append(dt)
        ctl.call("reset")
    ms = sorted(t * 1e3 for t in times)
    return {
        "median_ms": round(statistics.median(ms), 2),
        "max_ms": round(ms[-1], 2),
        "refused": failures,
    }


def run(shared: Path) -> dict[str, Any]:
    from omnisort_hw.service.client import Client
    from omnisort_hw.service.loadgen import (
        StatusPoller,
        idle_connections,
        never_reading_flood,
        rss_bytes,
    )

    out: dict[str, Any] = {"devices": f"simulated cell (scene sorting, {WIDTH}x{WIDTH} camera)"}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        svc = sim_service(tmp, "overflow_grace_s = 60.0\nwrite_timeout_s = 2.0\n")
        host, port = svc.host, svc.port
        try:
            with Client(host, port) as ctl:
                out["estop_unloaded"] = _estops(ctl, host, port)
                sources = [f"127.0.0.{2 + i}" for i in range(13)]
                with idle_connections(host, port, IDLE, sources):
                    time.sleep(0.5)
                    out[f"estop_with_{IDLE}_idle_connections"] = _estops(
                        ctl, host, port, "127.0.0.100"
                    )
                with idle_connections(host, port, 63, sources[:4]):
                    time.sleep(0.5)
                    out["estop_with_every_client_slot_held"] = _estops(
                        ctl, host, port, "127.0.0.100"
                    )
            rss0 = rss_bytes(svc.proc.pid)
            peak = [rss0]
            done = threading.Event()

            def sample() -> None:
                while not done.wait(0.05):
                    peak[0] = max(peak[0], rss_bytes(svc.proc.pid))

            sampler = threading.Thread(target=sample, daemon=True)
            sampler.start()
            with StatusPoller(host, port, period_s=0.02) as poller:
                flood = never_reading_flood(host, port, FLOOD, hold_s=10.0)
            done.set()
            sampler.join(5)
            out["never_reading_client"] = {
                "requests_sent": flood.sent,
                "dropped_by_service": flood.dropped_by_server,
                "rss_before_mb": round(rss0 / 1e6, 1),
                "rss_growth_mb": round((peak[0] - rss0) / 1e6, 1),
                "others_status": poller.summary(),
            }
        finally:
            out["service_exit_code"] = svc.stop()
    return out
