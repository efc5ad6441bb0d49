"""The service's jobs: one long command at a time on its own thread, refused with `busy`
while one runs and with `motion_refused` in `fault`; stop and estop cancel it and keep
stopping the arm until it has ended; its progress events and heartbeats reach the client
before its reply, never after; a job that outlives its timeout is cancelled and the arm
stopped.

`JobRunner` is a part of `server.Service` (its base class), kept apart because this is how a
job runs and ends and the rest of the service is its wire and its life cycle.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

from omnisort_hw.pipeline.replies import ResetReply, StopReply
from omnisort_hw.service import protocol as proto
from omnisort_hw.service.error_replies import error_from_exception
from omnisort_hw.service.handlers import HANDLERS, Context
from omnisort_hw.service.protocol import Emit
from omnisort_hw.service.states import Job, State, StateMachine

R = TypeVar("R")

if TYPE_CHECKING:
    from omnisort_hw.cell.cell import Cell
    from omnisort_hw.config.service import ServiceConfig
    from omnisort_hw.service.status_reply import ServiceStatus

log = logging.getLogger("omnisort.service")

PROGRESS_PERIOD_S = 1.0


class JobRunner:
    """The job side of `server.Service` (see the module doc)."""

    cell: Cell
    config: ServiceConfig
    states: StateMachine
    _job: Job | None
    _job_lock: threading.Lock

    if TYPE_CHECKING:  # defined by `Service`

        def service_status(self) -> ServiceStatus: ...

        def _then_refresh(self, fn: Callable[[], R]) -> R: ...

    def _stop(self) -> StopReply:
        job = self._job
        if job is not None:
            job.stopped_by = "stop"
            job.cancel.set()
        problems = self.cell.stop_motion()
        if job is not None:
            self._keep_stopping(job)
        if self.states.state != State.FAULT:
            what = f"{job.cmd} stopped" if job is not None else "stop requested"
            self.states.set(State.STOPPED, what)
        return StopReply(job.cmd if job is not None else None, self.states.state.value, problems)

    def _estop(self) -> StopReply:
        job = self._job
        if job is not None:
            job.stopped_by = "estop"
            job.cancel.set()
        # Fault first: whatever is about to switch on from now is refused by the guard.
        self.states.set(State.FAULT, "emergency stop requested by a client; send reset")
        problems = self.cell.emergency_stop()
        if job is not None:
            self._keep_stopping(job)
        return StopReply(job.cmd if job is not None else None, self.states.state.value, problems)

    def _keep_stopping(self, job: Job, period_s: float = 0.1, limit_s: float = 10.0) -> None:
        """Stop the arm again every `period_s` until `job` ends (closes the window in which a
        cancelled job could still start a motion); runs in its own daemon thread."""

        def loop() -> None:
            deadline = time.monotonic() + limit_s
            while self._job is job and time.monotonic() < deadline:
                time.sleep(period_s)
                if self._job is job:
                    self.cell.stop_motion()

        threading.Thread(target=loop, name="keep-stopping", daemon=True).start()

    def _reset(self, gripper_empty: bool = False) -> ResetReply:
        with self._job_lock:
            if self._job is not None:
                raise proto.ProtocolError(
                    proto.BUSY, f"{self._job.cmd} is running; send stop first"
                )
            back, lost = self.cell.devices.reconnect_lost()
            safety = self.cell.check_safe_to_resume()
            if gripper_empty:
                self.cell.confirm_gripper_empty()
            old = self.states.state
            self.states.set(State.IDLE, f"reset from {old.value}")
        return ResetReply(
            state=State.IDLE.value, previous=old.value, reconnected=back, lost=lost, arm=safety
        )

    async def _run_job(self, req: proto.Request, emit: Emit | None = None) -> dict[str, Any]:
        spec = req.command
        with self._job_lock:
            if self._job is not None:
                running = self._job
                raise proto.ProtocolError(
                    proto.BUSY,
                    f"{running.cmd} (request {running.request_id}) is running for "
                    f"{time.monotonic() - running.started:.1f} s; one motion or job at a time: "
                    "wait for it or send stop",
                    running=running.cmd,
                )
            if self.states.state == State.FAULT:
                raise proto.ProtocolError(
                    proto.MOTION_REFUSED,
                    f"the cell is in fault ({self.states.reason}); clear the cause and send reset",
                )
            expected = self.cell.journal.expected_s(req.cmd, req.args)
            job = Job(req.cmd, req.id, State(spec.job_state or State.MOVING), expected_s=expected)
            self._job = job
            resting = self.states.state
            self.states.set(job.state, f"{req.cmd} (request {req.id})")
        self.cell.runlog.event("service/requests", f"{req.cmd} {req.args}")
        loop = asyncio.get_running_loop()
        done: asyncio.Future[dict[str, Any]] = loop.create_future()

        replied = threading.Event()  # set once the reply is decided: no event after it

        def report(event: dict[str, Any]) -> None:
            job.report(event)
            self.cell.journal.progress(event)
            if emit is not None and not replied.is_set():
                with contextlib.suppress(RuntimeError):  # the loop is gone at shutdown
                    loop.call_soon_threadsafe(_emit_unless, replied, emit, event)

        ctx = Context(self.cell, job.cancel, self.service_status, report)
        thread = threading.Thread(
            target=self._job_thread,
            args=(job, req, ctx, resting, loop, done),
            name=f"job-{req.cmd}",
            daemon=True,
        )
        thread.start()
        beats = asyncio.ensure_future(self._heartbeats(job, emit)) if emit else None
        try:
            return await asyncio.wait_for(asyncio.shield(done), self.config.job_timeout_s)
        except TimeoutError:
            job.stopped_by = "timeout"
            job.cancel.set()
            await asyncio.to_thread(self.cell.stop_motion)
            return proto.error_reply(
                req.id,
                proto.DEVICE_ERROR,
                f"{req.cmd} did not finish within {self.config.job_timeout_s:g} s; arm stopped",
                device_code="device_timeout",
            )
        finally:
            replied.set()
            if beats is not None:
                beats.cancel()

    async def _heartbeats(self, job: Job, emit: Emit) -> None:
        """`{"stage": "started"}` with what the last such job took here (`expected_s`), then
        the running time every PROGRESS_PERIOD_S, so a client shows a job that reports nothing
        (a calibration) as alive rather than silent, and for how long to expect it."""
        emit({"stage": "started", "cmd": job.cmd, "expected_s": job.expected_s})
        while True:
            await asyncio.sleep(PROGRESS_PERIOD_S)
            emit({"running_s": round(time.monotonic() - job.started, 1)})

    def _job_thread(
        self,
        job: Job,
        req: proto.Request,
        ctx: Context,
        resting: State,
        loop: asyncio.AbstractEventLoop,
        done: asyncio.Future[dict[str, Any]],
    ) -> None:
        reply: dict[str, Any]
        journal = self.cell.journal
        journal.start(req.cmd, req.id, req.args)
        try:
            result = self._then_refresh(lambda: HANDLERS[req.cmd](ctx, req.payload))
            if job.cancel.is_set():
                reply = self._stopped_reply(job, req)
            else:
                reply = proto.ok_reply(req.id, result)
                self._end_job(job, State.IDLE, f"{req.cmd} done")
        except BaseException as exc:
            code, msg, details = error_from_exception(exc)
            if code == proto.INTERNAL and not job.cancel.is_set():
                log.error("%s failed", req.cmd, exc_info=exc)
            if job.cancel.is_set():
                reply = self._stopped_reply(job, req, msg)
            elif _faults_cell(job, code, exc):
                reply = proto.error_reply(req.id, code, msg, **details)
                self._end_job(job, State.FAULT, f"{req.cmd} failed: {msg}")
            else:
                reply = proto.error_reply(req.id, code, msg, **details)
                self._end_job(job, resting, f"{req.cmd} refused: {code}")
        finally:
            with self._job_lock:
                if self._job is job:
                    self._job = None
        if reply["ok"]:
            journal.finish("done", f"{req.cmd} done")
        else:
            err = reply["error"]
            stopped = err["code"] == proto.STOPPED
            journal.finish("stopped" if stopped else "failed", f"{err['code']}: {err['message']}")
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(_set_if_pending, done, reply)

    def _stopped_reply(self, job: Job, req: proto.Request, detail: str = "") -> dict[str, Any]:
        by = job.stopped_by or "stop"
        msg = f"{req.cmd} was stopped by {by}" + (f" ({detail})" if detail else "")
        return proto.error_reply(req.id, proto.STOPPED, msg, stopped_by=by)

    def _end_job(self, job: Job, new: State, reason: str) -> None:
        with self._job_lock:
            if self.states.state == job.state and not job.cancel.is_set():
                self.states.set(new, reason)


MOTION_STATES = frozenset({State.MOVING, State.SORTING})


def _faults_cell(job: Job, code: str, exc: BaseException) -> bool:
    """Whether a job's failure latches `fault`: a device or internal failure while the arm
    may be moving. A bad file, a missing board or a camera that times out during a
    calibration or a map is that request's error and nothing more."""
    return (
        job.state in MOTION_STATES
        and code in (proto.DEVICE_ERROR, proto.INTERNAL)
        and getattr(exc, "faults_cell", True)
    )


def _emit_unless(replied: threading.Event, emit: Emit, event: dict[str, Any]) -> None:
    """In the loop: forward a job's event unless its reply is already decided (a job that
    timed out still reports as it winds down; its events must not follow the reply)."""
    if not replied.is_set():
        emit(event)


def _set_if_pending(fut: asyncio.Future[dict[str, Any]], value: dict[str, Any]) -> None:
    if not fut.done():
        fut.set_result(value)
