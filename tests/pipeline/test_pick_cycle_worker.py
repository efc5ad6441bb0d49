"""Pick planning in the compute worker: the queue goes there and comes back with the same plan
as planned in the caller; a worker killed mid-plan is a typed `internal` error that leaves the
queue as it was, and a fresh worker plans the next pick; a cancel returns no plan."""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from omnisort_hw.cell.compute_worker import ComputeWorker, WorkerError
from omnisort_hw.core.pick_planning import Planner
from omnisort_hw.pipeline.pick_cycle import InCaller, PickQueue
from sim_backend.sort_harness import sim_sort_config
from tests.pipeline.sorting_scene import T_SB_of, make_cube, sorting_scene

WAIT_S = 60.0  # bound of every wait (the worker's start imports numpy, cv2, scipy)


class _StuckPlanner(Planner):
    """A planner whose planning never ends (the worker is killed or cancelled meanwhile)."""

    def plan_pick(self, *a: Any, **k: Any) -> Any:
        time.sleep(WAIT_S)
        raise AssertionError("the stuck planner was not ended")


REFUSED: dict[int, list[tuple[int, str]]] = {}  # id(queue) -> the refusals reported to it


def _queue(planner_cls: type[Planner] = Planner) -> PickQueue:
    from drivers.base import MotionLimits

    scene = sorting_scene()
    box = MotionLimits(workspace_min_mm=(-1100.0, -1100.0, 5.0), workspace_max_mm=(1100.0,) * 3)
    planner = planner_cls(
        sim_sort_config(scene), T_SB_of(scene), workspace_check=box.check_position
    )
    cubes = [
        make_cube("red", (600.0, -150.0, 50.0), yaw=20.0),
        make_cube("blue", (650.0, 150.0, 50.0), yaw=-10.0),
        make_cube("orange", (550.0, 0.0, 50.0)),  # no bin for orange: refused
    ]
    refused: list[tuple[int, str]] = []
    queue = PickQueue(planner, cubes, [2, 0, 1], lambda i, r: refused.append((i, r)))
    REFUSED[id(queue)] = refused
    return queue


@pytest.fixture
def worker() -> ComputeWorker:
    w = ComputeWorker()
    yield w
    w.close()


def test_the_worker_plans_as_the_caller_does(worker: ComputeWorker) -> None:
    here, there = _queue(), _queue()
    never = threading.Event()
    a = here.next_plan_via(InCaller(), here.planner.home, never)
    b = there.next_plan_via(worker, there.planner.home, never)
    assert a is not None and b is not None and a[0] == b[0] == 0
    np.testing.assert_allclose(a[1].end_q, b[1].end_q)
    assert [m.what for m in a[1].moves] == [m.what for m in b[1].moves]
    for q in (here, there):  # the refusal reached the caller's callback, the state came back
        assert [i for i, _ in REFUSED[id(q)]] == [2]
        assert q.todo == [1] and q.gone == {0} and len(q.plan_s) == 1
        assert q.planner.bin_fill["red"] == 1
    c = there.next_plan_via(worker, b[1].end_q, never)
    assert c is not None and c[0] == 1 and there.planner.bin_fill["blue"] == 1


def test_a_worker_killed_mid_plan_leaves_the_queue_as_it_was(worker: ComputeWorker) -> None:
    stuck = _queue(_StuckPlanner)
    before = (list(stuck.todo), set(stuck.gone), dict(stuck.planner.bin_fill))
    errors: list[BaseException] = []

    def plan() -> None:
        try:
            stuck.next_plan_via(worker, stuck.planner.home, threading.Event())
        except BaseException as exc:
            errors.append(exc)

    t = threading.Thread(target=plan)
    t.start()
    deadline = time.monotonic() + WAIT_S
    while worker.pid is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert worker.pid is not None, "the worker did not start"
    time.sleep(0.5)  # the queue has reached the worker, which plans
    os.kill(worker.pid, signal.SIGKILL)
    t.join(WAIT_S)
    assert not t.is_alive() and len(errors) == 1
    assert isinstance(errors[0], WorkerError) and errors[0].code == "internal"
    assert (list(stuck.todo), set(stuck.gone), dict(stuck.planner.bin_fill)) == before
    fresh = _queue()
    job = fresh.next_plan_via(worker, fresh.planner.home, threading.Event())
    assert job is not None and job[0] == 0 and worker.restarts == 1


def test_a_cancel_during_planning_returns_no_plan(worker: ComputeWorker) -> None:
    stuck = _queue(_StuckPlanner)
    cancel = threading.Event()
    threading.Timer(1.0, cancel.set).start()
    assert stuck.next_plan_via(worker, stuck.planner.home, cancel) is None
    assert stuck.todo == [2, 0, 1] and stuck.gone == set()
