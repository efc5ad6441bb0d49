"""The compute worker: CPU-bound jobs in a child process; a worker that dies or hangs is a typed
`internal` error, a fresh one takes the next job, and nothing is half-saved."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from omnisort_hw.cell.compute_worker import ComputeWorker, WorkerError
from omnisort_hw.errors import InputError, MotionRefusedError
from tests.service.conftest import Harness

WAIT_S = 60.0  # bound of every wait below (the worker's start imports numpy, cv2, scipy)


def _square(x: float) -> float:
    return x * x


def _fail(path: str) -> None:
    raise InputError(f"{path}: not a readable image")


def _sleep(seconds: float) -> float:
    time.sleep(seconds)
    return seconds


def _wait_for(cond: Callable[[], bool], what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


@pytest.fixture
def worker() -> ComputeWorker:
    w = ComputeWorker()
    yield w
    w.close()


def test_results_and_typed_errors_come_back(worker: ComputeWorker) -> None:
    assert worker.call(_square, 3.0) == 9.0
    with pytest.raises(InputError, match=r"x\.png: not a readable image"):
        worker.call(_fail, "x.png")
    assert worker.call(_square, 4.0) == 16.0 and worker.restarts == 0


def test_a_killed_worker_is_an_internal_error_and_is_replaced(worker: ComputeWorker) -> None:
    worker.call(_square, 1.0)
    first = worker.pid
    assert first is not None
    errors: list[BaseException] = []

    def job() -> None:
        try:
            worker.call(_sleep, 30.0, what="calibration")
        except BaseException as exc:
            errors.append(exc)

    t = threading.Thread(target=job)
    t.start()
    time.sleep(0.3)  # the job is in the worker now
    os.kill(first, signal.SIGKILL)
    t.join(WAIT_S)
    assert not t.is_alive()
    assert len(errors) == 1 and isinstance(errors[0], WorkerError), errors
    assert errors[0].code == "internal" and "died" in str(errors[0])
    assert worker.call(_square, 5.0) == 25.0
    assert worker.pid not in (None, first) and worker.restarts == 1


def test_a_hung_worker_times_out_and_a_cancel_ends_the_job(worker: ComputeWorker) -> None:
    with pytest.raises(WorkerError, match=r"did not answer within 0\.5 s"):
        worker.call(_sleep, 30.0, timeout_s=0.5)
    cancel = threading.Event()
    threading.Timer(0.3, cancel.set).start()
    with pytest.raises(MotionRefusedError, match="cancelled"):
        worker.call(_sleep, 30.0, cancel=cancel)
    assert worker.call(_square, 2.0) == 4.0


def test_service_survives_a_worker_killed_mid_calibration(service: Harness, tmp_path: Path) -> None:
    """`calibrate intrinsics` with the worker killed mid-job: the reply is `internal`, nothing
    is saved, the service answers and is not in fault, and the next calibration runs."""
    from sim_backend.dataset import checkerboard_views

    views = tmp_path / "views"
    checkerboard_views(views, n=8, seed=2, width=480, progress=False)
    state = Path(service.cell.store.state_dir)

    def stored() -> dict[str, bytes]:
        """Every file of the state directory but the job journal, with its bytes."""
        return {
            str(p.relative_to(state)): p.read_bytes()
            for p in state.rglob("*")
            if p.is_file() and p.name != "job.json"
        }

    before = stored()
    compute = service.cell.compute
    args = {"what": "intrinsics", "folder": str(views), "square_mm": 116}
    replies: list[dict] = []

    def calibrate() -> None:
        with service.client(timeout_s=WAIT_S) as c:
            replies.append(c.call("calibrate", args))

    t = threading.Thread(target=calibrate)
    t.start()
    _wait_for(lambda: compute.pid is not None, "the compute worker to start")
    victim = compute.pid
    assert victim is not None
    os.kill(victim, signal.SIGKILL)
    t.join(WAIT_S)
    assert not t.is_alive() and len(replies) == 1
    reply = replies[0]
    assert not reply["ok"] and reply["error"]["code"] == "internal", reply
    assert "worker died" in reply["error"]["message"]
    assert stored() == before  # nothing saved, nothing half-written, no history entry
    with service.client(timeout_s=WAIT_S) as c:
        st = c.call("status")
        assert st["ok"] and st["result"]["state"] != "fault", st
        again = c.call("calibrate", args)
    assert again["ok"], again
    assert again["result"]["rms_px"] < 0.5
    assert Path(again["result"]["path"]).is_file()
    assert compute.pid not in (None, victim)
