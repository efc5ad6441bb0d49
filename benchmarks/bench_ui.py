"""The operator interface's cost to the service, its live view's speed and its memory, on the
simulated cell at 960 px (`omnisort serve` and `omnisort ui` each in its own process, the page
open in headless Debian Chromium, the arm paced to the wall clock).

- `status` during a sort, polled every 50 ms by the service's load generator
  (`loadgen.StatusPoller`): on a service with no page open, then on a fresh one (the same
  scene) with the page open and signed in, its live view running; twice each, alternating, so
  the spread between two runs of the same condition shows what a difference between the
  conditions is worth. The goal: p99 under 20 ms both, within 10 % of each other.
- The live view's pictures per second at 960 px: `view` asked back to back by the interface's
  own reader (`LiveFeed`, period 0) for 20 s on the idle cell (the simulator renders a still
  scene from its cached cube map), and during a sort of the cubes left (the arm moves: every
  picture is a new render).
- The interface's resident memory over 10 minutes with the page open (live view and status
  at their defaults), sampled every 30 s.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

WIDTH = 960
SORTED_PER_PHASE = 2
FPS_S = 20.0
SOAK_S = 600.0
SAMPLE_S = 30.0


def _p99_ms(latencies: list[float]) -> float:
    lat = sorted(latencies)
    return round(lat[int(0.99 * (len(lat) - 1))] * 1e3, 3)


def _sort_with_poller(port: int, pooled: list[float]) -> dict[str, Any]:
    from omnisort_hw.service.client import Client
    from omnisort_hw.service.loadgen import StatusPoller
    from tests.ui.ui_procs import TOKEN

    with StatusPoller("127.0.0.1", port) as poller:
        time.sleep(1.0)
        with Client("127.0.0.1", port, token=TOKEN, timeout_s=600) as c:
            t0 = time.perf_counter()
            reply = c.execute("sort", {"max_objects": SORTED_PER_PHASE})
            sort_s = time.perf_counter() - t0
        time.sleep(0.5)
    out = poller.summary()
    pooled += poller.latencies
    out["sort_s"] = round(sort_s, 1)
    out["sorted"] = reply["totals"]["sorted"]
    return out


def _open_page(url: str) -> Any:
    from tests.ui.browser_page import open_cell_page, wait_for

    driver, page = open_cell_page(url)
    wait_for("a live picture", lambda: page.text("view-note").startswith("picture"), 30)
    return driver


def _fps(port: int, during_sort: bool) -> dict[str, Any]:
    import threading

    from omnisort_hw.service.client import Client
    from omnisort_hw.ui.link import ServiceLink
    from omnisort_hw.ui.live_feed import LiveFeed
    from tests.ui.ui_procs import TOKEN

    link = ServiceLink("127.0.0.1", port, period_s=1.0)
    feed = LiveFeed(link, period_s=0.0, width_px=WIDTH)
    feed.watch()
    sorting = threading.Event()

    def sort() -> None:
        with Client("127.0.0.1", port, token=TOKEN, timeout_s=600) as c:
            sorting.set()
            c.execute("sort")

    try:
        time.sleep(3.0)  # the first picture
        job = threading.Thread(target=sort, daemon=True)
        if during_sort:
            job.start()
            sorting.wait(10)
            time.sleep(3.0)  # past the capture, into the picks
        first = feed.received
        t0 = time.perf_counter()
        time.sleep(FPS_S)
        received = feed.received - first
        elapsed = time.perf_counter() - t0
        if during_sort:
            job.join(600)
        last = feed.picture
        assert last is not None and feed.problem is None, feed.problem
        return {
            "pictures_per_s": round(received / elapsed, 2),
            "width_px": last.width,
            "jpeg_kb": round(len(last.base64) * 3 / 4 / 1024, 1),
        }
    finally:
        feed.unwatch()
        feed.close()


def _memory(ui_pid: int) -> dict[str, Any]:
    from omnisort_hw.service.loadgen import rss_bytes

    samples = []
    t0 = time.monotonic()
    while True:
        samples.append((round(time.monotonic() - t0), rss_bytes(ui_pid) / 2**20))
        if time.monotonic() - t0 >= SOAK_S:
            break
        time.sleep(SAMPLE_S)
    first, last = samples[0][1], samples[-1][1]
    half = [mb for t, mb in samples if t >= SOAK_S / 2]
    return {
        "minutes": round(samples[-1][0] / 60, 1),
        "rss_mb_start": round(first, 1),
        "rss_mb_end": round(last, 1),
        "rss_mb_max": round(max(mb for _, mb in samples), 1),
        "rss_mb_second_half_spread": round(max(half) - min(half), 1),
        "samples": [[t, round(mb, 1)] for t, mb in samples],
    }


def run(shared: Path) -> dict[str, Any]:
    from omnisort_hw.service.launch import start_service
    from tests.ui.ui_procs import quit_chromium, sim_cell_file, start_ui, stop_process

    out: dict[str, Any] = {"cell": f"simulated cell (scene sorting, {WIDTH} px), arm in real time"}
    pooled: dict[str, list[float]] = {"no_page": [], "page_open": []}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        (tmp / "cell").mkdir()
        config = sim_cell_file(tmp / "cell", width=WIDTH, realtime=True)
        state = config.parent / "state"
        pristine = {p.name: p.read_bytes() for p in state.glob("*.json")}

        def fresh_state() -> None:
            for p in state.glob("*"):
                if p.is_file():
                    p.unlink()
            for name, data in pristine.items():
                (state / name).write_bytes(data)

        for run_no in (1, 2):
            fresh_state()
            with start_service(config, tmp / f"no_page{run_no}") as svc:
                out[f"status_during_sort_no_page_{run_no}"] = _sort_with_poller(
                    svc.port, pooled["no_page"]
                )
            fresh_state()
            with start_service(config, tmp / f"page{run_no}") as svc:
                ui_proc, url = start_ui(config, svc.port, tmp)
                driver = _open_page(url)
                try:
                    out[f"status_during_sort_page_open_{run_no}"] = _sort_with_poller(
                        svc.port, pooled["page_open"]
                    )
                    if run_no == 2:
                        out["live_view_960"] = _fps(svc.port, during_sort=False)
                        out["live_view_960_during_sort"] = _fps(svc.port, during_sort=True)
                        out["ui_memory"] = _memory(ui_proc.pid)
                finally:
                    quit_chromium(driver)
                    stop_process(ui_proc)
    a, b = _p99_ms(pooled["no_page"]), _p99_ms(pooled["page_open"])
    out["status_p99_ms"] = {"no_page": a, "page_open": b, "page_over_no_page": round(b / a, 3)}
    runs = {
        cond: [out[f"status_during_sort_{cond}_{n}"]["p99_ms"] for n in (1, 2)]
        for cond in ("no_page", "page_open")
    }
    out["status_p99_run_to_run_ratio"] = {
        cond: round(max(v) / min(v), 3) for cond, v in runs.items()
    }
    out["status_p99_goal_met"] = bool(a < 20 and b < 20 and abs(b - a) <= 0.1 * a)
    return out
