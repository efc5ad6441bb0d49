"""The interface's one job at a time, shared by every browser: a page that cannot start one is
told whether the running job was started in its own browser or another (it once said "started
here" to every browser), and the job is sent as a typed call. The peer is a real TCP listener
on loopback that takes the request and answers when the test lets it."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
from collections.abc import Iterator

import pytest

from omnisort_hw.config.ui import UiConfig
from omnisort_hw.pipeline.replies import MapReply, VerdictReply
from omnisort_hw.pipeline.requests import DetectRequest, MapRequest
from omnisort_hw.request_fields import wire_args
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.detection_view import LiveDetection
from omnisort_hw.ui.job_runner import JobRunner
from omnisort_hw.ui.link import CellCommands, ServiceLink, call_of
from omnisort_hw.ui.live_feed import LiveFeed
from omnisort_hw.ui.operators import Operators
from omnisort_hw.ui.session import BrowserSession
from omnisort_hw.wire_records import to_wire
from tests.ui.browser_page import wait_for

WAIT_S = 10.0  # a guard against a hang, not a latency bound
MAPPED = MapReply(
    points=7,
    points_on_plane=7,
    echoes_dropped=0,
    stripe_ends_dropped=0,
    segments=[],
    image={"path": "on.png"},
    verdict=VerdictReply("laser map", ()),
)


@pytest.fixture()
def peer() -> Iterator[tuple[int, threading.Event, list[dict[str, object]]]]:
    """A service stand-in at a loopback port: it records each request line and answers it
    with an ok reply once `answer` is set: MAPPED, or what a test put in `seen[1]`."""
    answer = threading.Event()
    seen: list[dict[str, object]] = []
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(WAIT_S)

    def serve() -> None:
        with server:
            conn, _ = server.accept()
            with conn, conn.makefile("rwb") as f:
                request = json.loads(f.readline())
                seen.append(request)
                answer.wait(WAIT_S)
                result = seen[1] if len(seen) > 1 else to_wire(MAPPED)
                reply = {"id": request.get("id"), "ok": True, "result": result}
                f.write(json.dumps(reply).encode() + b"\n")
                f.flush()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()[1], answer, seen
    answer.set()
    thread.join(WAIT_S)


def test_a_second_browser_is_told_the_job_is_another_browsers(peer) -> None:
    port, answer, seen = peer
    jobs = JobRunner(ServiceLink("127.0.0.1", port, timeout_s=WAIT_S))
    assert jobs.busy("browser-a") is None
    jobs.start(call_of(CellCommands.map, MapRequest(points=True)), "token", "browser-a")
    wait_for("the request at the peer", lambda: seen, WAIT_S)
    assert seen[0]["cmd"] == "map" and seen[0]["args"] == wire_args(MapRequest(points=True)), seen
    assert jobs.busy("browser-a") == "map started in this browser is still running"
    assert jobs.busy("browser-b") == "map started from another browser is still running"
    with pytest.raises(RuntimeError, match="map started from another browser"):
        jobs.start(call_of(CellCommands.locate), "token", "browser-b")
    answer.set()
    wait_for("the job's end", lambda: jobs.busy("browser-b") is None, WAIT_S)
    assert jobs.busy("browser-a") is None
    assert jobs.last is not None and jobs.last.ok and jobs.last.cmd == "map"
    assert jobs.result(CellCommands.map) == MAPPED  # read as its record
    assert jobs.result(CellCommands.locate) is None


def test_a_reply_that_does_not_fit_its_record_ends_the_job_saying_where(peer) -> None:
    """A service of another version: the job ends failed, naming the record's field, and
    the page can start the next one (nothing waits for an end that never comes)."""
    port, answer, seen = peer
    jobs = JobRunner(ServiceLink("127.0.0.1", port, timeout_s=WAIT_S))
    jobs.start(call_of(CellCommands.map), "token", "browser-a")
    wait_for("the request at the peer", lambda: seen, WAIT_S)
    seen.append({"points_on_plane": 7})  # an old reply: no segments, no verdict...
    answer.set()
    wait_for("the job's end", lambda: jobs.busy("browser-a") is None, WAIT_S)
    assert jobs.last is not None and not jobs.last.ok
    assert "map: the service's reply does not fit MapReply." in jobs.last.message
    assert jobs.result(CellCommands.map) is None


def test_a_live_detection_waits_while_a_job_runs(peer) -> None:
    """While a job of the interface runs, a step's live detection asks nothing of the service
    (the job's frames are its own, and the cell's cores its work); after it, it may ask."""
    port, answer, seen = peer
    link = ServiceLink("127.0.0.1", port, timeout_s=WAIT_S)  # its status is not read here
    config = UiConfig()
    ctx = UiContext(config, link, Operators(link, True), JobRunner(link), LiveFeed(link, 1, 320))
    detection = LiveDetection(BrowserSession(ctx, "browser-a"), DetectRequest, "detect")
    detection.active = True
    assert ctx.jobs.running is None and not detection.cell_busy()
    ctx.jobs.start(call_of(CellCommands.map), "token", "browser-a")
    wait_for("the request at the peer", lambda: seen, WAIT_S)
    assert ctx.jobs.running == "map" and detection.cell_busy()
    asyncio.run(detection.tick())
    assert [r["cmd"] for r in seen] == ["map"] and detection.last is None  # nothing asked
    answer.set()
    wait_for("the job's end", lambda: ctx.jobs.running is None, WAIT_S)
    assert not detection.cell_busy()
