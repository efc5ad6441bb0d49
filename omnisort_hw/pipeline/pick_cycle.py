"""The pick cycle's bookkeeping: which cube to plan next, and where the cycle's time goes.

`PickQueue` hands out the next pick plan: the first cube still to sort whose whole pick plans
collision-free from where the previous pick ends (over its bin, so the arm goes bin -> next cube
without a return home). Cubes already picked or in flight are not obstacles any more; a cube
refused because another one was in the way is tried again once a cube has gone; other
refusals are final. The queue is used by one thread at a time: the sorter plans the next pick
on a helper thread while the arm carries out the current one, and waits for that plan only
when the arm needs it. In the service the planning itself runs in the compute worker
(`next_plan_via`: the queue is sent there and comes back with the plan), so the service's
process keeps its GIL for the event loop.

`CycleTimes` records a run's time the way a cell's cycle is judged: the arm's motion (on the
arm's clock), the gripper's actions, the computation the arm waited for (not hidden behind
motion; wall time), the planned paths' time at the configured limits (the lower bound of
motion) and each plan's CPU time (the computation per pick on one core).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

import numpy as np

from omnisort_hw.core.cube_location import Cube
from omnisort_hw.core.pick_planning import BLOCKED, PickPlan, Planner
from omnisort_hw.errors import MotionRefusedError

T = TypeVar("T")


@dataclass
class CycleTimes:
    """Where a sorting run's time went (seconds; `plan_s` one entry per plan computed)."""

    picks: int = 0
    motion_s: float = 0.0
    gripper_s: float = 0.0
    planned_s: float = 0.0
    wait_s: float = 0.0
    locate_s: float = 0.0
    plan_s: list[float] = field(default_factory=list)

    def faster_than_real_time(self) -> bool:
        """Whether the arm's motions took less than 90 % of their planned time: more than a
        controller period's slack per move can explain, so the clock is not the arm's."""
        return self.planned_s > 0 and self.motion_s < 0.9 * self.planned_s

    def summary(self) -> dict[str, Any]:
        """Per-pick figures (None without a pick, or with a clock that is not the arm's):
        motion, gripper, waited computation, the planned lower bound, the cycle they add up to
        and picks per minute."""
        out: dict[str, Any] = {
            "picks": self.picks,
            "motion_s": round(self.motion_s, 3),
            "gripper_s": round(self.gripper_s, 3),
            "wait_s": round(self.wait_s, 3),
            "planned_s": round(self.planned_s, 3),
            "locate_s": round(self.locate_s, 3),
            "plans": len(self.plan_s),
            "plan_ms_mean": round(1e3 * float(np.mean(self.plan_s)), 1) if self.plan_s else None,
            "plan_ms_max": round(1e3 * float(np.max(self.plan_s)), 1) if self.plan_s else None,
        }
        n = self.picks
        cycle = (self.motion_s + self.gripper_s + self.wait_s) / n if n else None
        if self.faster_than_real_time():
            # A controller follows the plan's limits: no arm moves faster than planned. A
            # simulated arm not paced to the wall clock does, and its measured times then say
            # nothing of a cycle (50 picks/min beside a 6.4 s lower bound per pick).
            cycle = None
            out["clock"] = (
                f"the arm ran faster than real time ({self.motion_s:.2f} s of motion measured "
                f"against {self.planned_s:.2f} s planned): no cycle time, the planned lower "
                "bound stands"
            )
        out.update(
            motion_s_per_pick=round(self.motion_s / n, 3) if n and cycle else None,
            gripper_s_per_pick=round(self.gripper_s / n, 3) if n and cycle else None,
            wait_s_per_pick=round(self.wait_s / n, 3) if n and cycle else None,
            lower_bound_s_per_pick=round(self.planned_s / n, 3) if n else None,
            cycle_s_per_pick=round(cycle, 3) if cycle else None,
            picks_per_minute=round(60.0 / cycle, 2) if cycle else None,
        )
        return out


class Compute(Protocol):
    """Where CPU-bound work runs (`cell.compute_worker.ComputeWorker` or `InCaller`)."""

    def call(self, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T: ...

    def call_logged(self, fn: Callable[..., T], log: Any, *args: Any, **kwargs: Any) -> T: ...


class InCaller:
    """`ComputeWorker`'s interface, running the function in the caller's thread: for the CLI
    and the evaluations, which have no service to keep answering."""

    def call(
        self,
        fn: Callable[..., T],
        *args: Any,
        timeout_s: float | None = None,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        return fn(*args, **kwargs)

    def call_logged(
        self,
        fn: Callable[..., T],
        log: Any,
        *args: Any,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        return fn(*args, log=log, **kwargs)


def _never() -> bool:
    return False


def _next_plan_of(
    queue: PickQueue, q_from: np.ndarray
) -> tuple[PickQueue, tuple[int, PickPlan] | None, list[tuple[int, str]]]:
    """`queue.next_plan(q_from)` on a copy of the queue (in a worker): the updated copy, the
    result and the refusals met (the caller reports them)."""
    refusals: list[tuple[int, str]] = []
    queue.on_refused = lambda i, reason: refusals.append((i, reason))
    return queue, queue.next_plan(q_from), refusals


class PickQueue:
    """The cubes still to sort, planned one at a time from where the arm will be (see module)."""

    def __init__(
        self,
        planner: Planner,
        cubes: Sequence[Cube],
        todo: Sequence[int],
        on_refused: Callable[[int, str], None],
        cancelled: Callable[[], bool] = lambda: False,
    ) -> None:
        self.planner = planner
        self.cubes = list(cubes)
        self.todo = list(todo)
        self.on_refused = on_refused
        self.cancelled = cancelled
        self.gone: set[int] = set()
        self._tried_with: dict[int, int] = {}  # blocked cube -> len(gone) when it was tried
        self._reasons: dict[int, str] = {}
        self.plan_s: list[float] = []

    def next_plan(self, q_from: np.ndarray) -> tuple[int, PickPlan] | None:
        """The next cube's committed pick plan from joints `q_from`, or None when no cube left
        can be planned now (it marks the cube gone: the caller picks it next)."""
        t0 = time.thread_time()  # CPU time of this thread: the plan's computation
        try:
            for i in list(self.todo):
                if self.cancelled():
                    return None
                if self._tried_with.get(i) == len(self.gone):
                    continue  # blocked, and nothing has gone since it was tried
                others = [c for k, c in enumerate(self.cubes) if k != i and k not in self.gone]
                plan = self.planner.plan_pick(self.cubes[i], others, q_from, end_home=False)
                if plan.refused is None:
                    self.planner.commit(plan)
                    self.todo.remove(i)
                    self.gone.add(i)
                    self._tried_with.pop(i, None)
                    return i, plan
                if plan.refused.startswith(BLOCKED):
                    self._tried_with[i] = len(self.gone)
                    self._reasons[i] = plan.refused
                else:
                    self.todo.remove(i)
                    self.on_refused(i, plan.refused)
            return None
        finally:
            self.plan_s.append(time.thread_time() - t0)

    def next_plan_via(
        self, compute: Compute, q_from: np.ndarray, cancel: threading.Event
    ) -> tuple[int, PickPlan] | None:
        """`next_plan` computed by `compute` (a worker process: the queue travels there and
        back, so the caller's process is not held); None when cancelled meanwhile."""
        keep = self.on_refused, self.cancelled
        try:
            done, job, refusals = compute.call(
                _next_plan_of, self, q_from, cancel=cancel, what="pick planning"
            )
        except MotionRefusedError:
            if cancel.is_set():
                return None
            raise
        finally:
            self.on_refused, self.cancelled = keep
        self.__dict__.update(done.__dict__)
        self.on_refused, self.cancelled = keep
        for i, reason in refusals:
            self.on_refused(i, reason)
        return job

    def __getstate__(self) -> dict[str, Any]:
        """The queue without its callbacks (they stay with the caller)."""
        return {**self.__dict__, "on_refused": None, "cancelled": _never}

    def give_back(self, i: int, plan: PickPlan) -> None:
        """Undo the plan of cube i that will not be carried out: the cube is to sort again
        and its place in the bin is free again."""
        if plan.bin is not None:
            fill = self.planner.bin_fill
            fill[plan.bin.color] = max(0, fill.get(plan.bin.color, 0) - 1)
        self.gone.discard(i)
        self.todo.insert(0, i)

    def waiting(self) -> dict[int, str]:
        """Cubes left unsorted because another cube blocked them, with the reason."""
        return {i: self._reasons.get(i, BLOCKED) for i in self.todo}
