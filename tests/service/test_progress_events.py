"""Progress events on the protocol: a job asked with `"progress": true` sends event lines
(its id, no `ok`) before its reply; a request that did not ask gets none."""

from __future__ import annotations

import json

import pytest

from omnisort_hw.cli import main
from omnisort_hw.service.client import ClientError
from tests.service.conftest import TOKEN, Harness

pytestmark = pytest.mark.timeout(60)


def test_a_job_sends_its_events_before_the_reply(make_service) -> None:
    """A 1.5 s move: `started` first, then the running time (every PROGRESS_PERIOD_S), all
    under the request's id and before the reply; the order is checked, not the timing."""
    h: Harness = make_service(move_seconds=1.5)
    with h.client(timeout_s=30) as c:
        rid = c.send("move", {"joints_deg": [10, 0, 0, 0, 0, 0]}, progress=True)
        lines = []
        while True:
            line = c.read_reply()
            assert line["id"] == rid
            lines.append(line)
            if "ok" in line:
                break
        # Nothing follows the reply: the heartbeats stop with it (2 heartbeat periods).
        with pytest.raises(ClientError, match="no reply"):
            c.read_reply(timeout_s=2.0)
    *events, reply = lines
    assert reply["ok"], reply
    assert events and all(e["event"] == "progress" and "ok" not in e for e in events)
    assert events[0]["progress"] == {"stage": "started", "cmd": "move", "expected_s": None}
    times = [e["progress"]["running_s"] for e in events[1:]]
    assert times == sorted(times) and all(0 < t < 30 for t in times), times


def test_without_asking_there_are_no_events(make_service) -> None:
    h: Harness = make_service(move_seconds=1.5)
    with h.client(timeout_s=30) as c:
        rid = c.send("move", {"joints_deg": [10, 0, 0, 0, 0, 0]})
        first = c.read_reply()
    assert first["id"] == rid and first["ok"], first


def test_progress_must_be_a_boolean(make_service) -> None:
    h: Harness = make_service()
    with h.client() as c:
        c.send("status", progress="yes")
        r = c.read_reply()
    assert r["error"]["code"] == "bad_request" and "progress" in r["error"]["message"]


def test_ctl_status_is_one_screen_and_json_on_request(make_service, capsys) -> None:
    h: Harness = make_service(token=TOKEN)
    port = str(h.running.port)
    assert main(["ctl", "--port", port, "status"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].split()[:2] == ["state", "idle"], out
    assert any(line.startswith("motion") and "allowed" in line for line in lines), out
    assert any("camera" in line and "FAKE-CAM-1" in line for line in lines), out
    assert len(lines) <= 20 and max(map(len, lines)) <= 160, out
    assert main(["ctl", "--port", port, "--json", "status"]) == 0
    assert json.loads(capsys.readouterr().out)["result"]["state"] == "idle"


def test_the_summary_says_refused_when_drift_refuses_motion() -> None:
    """`motion_allowed` in status speaks of the calibration files; a detected drift refuses
    motion too, and the summary must not say "allowed" then."""
    from omnisort_hw.service.status_reading import summarise

    status = {
        "state": "idle",
        "motion_allowed": True,
        "calibration": {"files": {"camera": {"health": "ok"}}, "robot_registered": True},
        "drift": {"motion_refused": True, "reason": "camera turned 0.4 deg", "last": None},
    }
    motion = next(line for line in summarise(status).splitlines() if line.startswith("motion"))
    assert "REFUSED" in motion and "camera turned 0.4 deg" in motion, motion
