"""The typed client: one method per protocol command over one `execute()`; a method takes the
command's request record and returns the result, an error reply is a `CommandError` with its
code and field, and a job's progress events reach the caller."""

from __future__ import annotations

import inspect
import subprocess
import sys
import time

import pytest

from omnisort_hw.pipeline.replies import LaserReply, MoveReply
from omnisort_hw.pipeline.requests import LaserRequest, MoveRequest, SortRequest
from omnisort_hw.request_fields import build, wire_args
from omnisort_hw.service.client import Client, CommandError
from omnisort_hw.service.protocol import COMMANDS
from omnisort_hw.service.status_reply import StatusReply
from tests.service.conftest import TOKEN, Harness

pytestmark = pytest.mark.timeout(60)


def test_every_command_has_its_method_taking_its_request_record() -> None:
    for name, spec in COMMANDS.items():
        method = getattr(Client, name, None)
        assert callable(method), f"Client has no method for {name}"
        params = inspect.signature(method).parameters
        if spec.request is not None:
            assert spec.request.__name__ in str(params["request"].annotation), name
        else:
            assert "request" not in params, name


def test_the_client_starts_without_the_numerical_stack() -> None:
    """`omnisort ctl`, the PLC face and the interface import the client: its command and reply
    types must not load numpy or OpenCV (a second at every `ctl` call)."""
    code = (
        "import sys, omnisort_hw.service.client; "
        "print(sorted(m for m in ('numpy', 'cv2', 'scipy') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr


def test_wire_args_give_the_record_back() -> None:
    requests = [
        MoveRequest(joints_deg=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0), speed_deg_s=10.0),
        MoveRequest(matrix=tuple(tuple(float(i == j) for j in range(4)) for i in range(4))),
        SortRequest(max_objects=2, colors=("red",), register=True),
    ]
    for request in requests:
        assert build(type(request), wire_args(request)) == request
    assert wire_args(None) == {}


def test_typed_calls_against_the_service(make_service) -> None:
    h: Harness = make_service(token=TOKEN, move_seconds=1.2)
    with h.client(token=TOKEN, timeout_s=30) as c:
        status = c.status()
        assert status["state"] == "idle"
        required, optional = StatusReply.__required_keys__, StatusReply.__optional_keys__
        assert required <= set(status) <= required | optional  # the declared reply
        assert c.laser(LaserRequest(on=True)) == LaserReply(on=True)
        assert c.laser() == LaserReply(on=True)  # omitted: read back
        events: list[dict] = []
        t0 = time.monotonic()
        reached = c.move(MoveRequest(joints_deg=(10.0, 0, 0, 0, 0, 0)), on_event=events.append)
        took = time.monotonic() - t0
        assert isinstance(reached, MoveReply) and len(reached.tcp_pose) == 4
        assert reached.joints_deg == pytest.approx([10.0, 0, 0, 0, 0, 0], abs=0.01)
        assert events[0] == {"stage": "started", "cmd": "move", "expected_s": None}, events
        # The next move is told what the last one took on this cell (rounded to 0.1 s).
        again: list[dict] = []
        c.move(MoveRequest(joints_deg=(0.0, 0, 0, 0, 0, 0)), on_event=again.append)
        expected = again[0]["expected_s"]
        assert 1.2 <= expected <= took + 0.05, (expected, took)
        with pytest.raises(CommandError) as refused:
            c.move(MoveRequest(joints_deg=(1.0, 2.0)))
        assert refused.value.code == "bad_argument"
        assert refused.value.details["field"] == "joints_deg"
        assert "calibrate" in c.describe().commands
        st = c.stop()
        assert (st.stopped_job, st.state) == (None, "stopped"), st
        reset = c.reset()
        assert (reset.previous, reset.state, reset.lost) == ("stopped", "idle", {}), reset
    with h.client(token="wrong-token-xxxxxxxx") as c, pytest.raises(CommandError) as denied:
        c.laser(LaserRequest(on=False))
    assert denied.value.code == "unauthorized"
