"""The service: an asyncio TCP server, the state machine, one job at a time, clean shutdown.

Threads and what runs where:
- the event loop reads and writes every connection, validates requests, checks tokens, keeps
  the state machine, pings the systemd watchdog and never touches a device;
- `quick` pool (status, capture, laser) and `safety` pool (stop, estop) run device calls, so
  `status`, `stop` and `estop` are answered while a long command runs;
- one daemon thread per job (calibrate, map, register_robot, locate, move, sort); a second job
  while one runs is refused with `busy`.

Replies carry the request's id; a connection may have several requests in flight, so the reply
to a long command arrives when it ends while other requests on the same connection are answered
meanwhile.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import os
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from typing import Any, TypeVar

from omnisort_hw import __version__
from omnisort_hw.cell.cell import Cell
from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.errors import MotionRefusedError, OmnisortError
from omnisort_hw.pipeline.replies import ShutdownReply
from omnisort_hw.service import protocol as proto
from omnisort_hw.service.connection import (
    READ_CHUNK,
    Admission,
)
from omnisort_hw.service.error_replies import error_from_exception
from omnisort_hw.service.handlers import HANDLERS, Context, Reply
from omnisort_hw.service.jobs import JobRunner
from omnisort_hw.service.listener import check_exposure
from omnisort_hw.service.pool import DaemonPool
from omnisort_hw.service.protocol import Emit
from omnisort_hw.service.states import Job, State, StateMachine, Transition
from omnisort_hw.service.status_reply import ServiceRecord, ServiceStatus
from omnisort_hw.service.systemd import Notifier
from omnisort_hw.service.transport import Transport
from omnisort_hw.wire_records import to_wire

R = TypeVar("R")
log = logging.getLogger("omnisort.service")

SWITCH_INTERVAL_S = 0.001
OVERFLOW_PER_CLIENT = 4
LOG_CHECK_S = 1.0


class Service(Transport, JobRunner):
    """One cell behind the line-delimited JSON protocol."""

    def __init__(
        self,
        cell: Cell,
        config: ServiceConfig,
        notifier: Notifier | None = None,
    ) -> None:
        check_exposure(config)
        self.cell = cell
        self.config = config
        self.notifier = notifier or Notifier({})
        self.states = StateMachine(self._on_transition)
        cell.actuation_guard = self._check_may_actuate
        cell.drift.busy = lambda: self._job is not None
        self._recover_interrupted_job()
        self._job: Job | None = None
        self._job_lock = threading.Lock()
        self._quick = DaemonPool("quick", 6)
        self._safety = DaemonPool("safety", 2)
        self._server: asyncio.base_events.Server | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop_requested: asyncio.Event | None = None
        self._stop_reason = ""
        self._clients: set[asyncio.StreamWriter] = set()
        self._started = time.monotonic()
        self.address: tuple[str, int] | None = None
        self.counters = {
            "requests": 0,
            "errors": 0,
            "connections": 0,
            "slow_clients_dropped": 0,
        }
        self.errors_by_code: dict[str, int] = {}
        self.last_error: tuple[str, str, float] | None = None  # code, message, monotonic time
        self._admission = Admission(
            config.max_clients,
            config.max_clients_per_peer,
            OVERFLOW_PER_CLIENT * config.max_clients,
        )
        self.exit_problems: list[str] = []
        self.log_check_s = LOG_CHECK_S
        self._roll: asyncio.Future[bool] | None = None  # the run log roll in flight

    # -- state -----------------------------------------------------------------------------

    def _on_transition(self, tr: Transition) -> None:
        self.cell.runlog.event("service/state", f"{tr.old} -> {tr.new}: {tr.reason}")
        self.notifier.status(f"{tr.new}: {tr.reason}")

    def _recover_interrupted_job(self) -> None:
        """A job the previous process did not finish: report it and refuse motion until reset
        (nothing resumes by itself)."""
        rec = self.cell.journal.recover()
        if rec is None:
            return
        cube = rec.get("in_flight")
        flight = (
            f"; cube {cube['cube']} ({cube['color']}, for bin {cube['bin']}) was {cube['phase']}"
            if cube
            else ""
        )
        msg = (
            f"{rec['job']} (request {rec['request_id']}) was interrupted: {rec['outcome']} after "
            f"{len(rec['progress'])} progress event(s){flight}; check the cell, then send reset"
        )
        log.error("%s", msg)
        self.states.set(State.FAULT, msg)

    def service_status(self) -> ServiceStatus:
        """The service's part of the `status` reply."""
        job = self._job
        return {
            **self.states.snapshot(),
            "job": job.describe() if job is not None else None,
            "last_run": self.cell.journal.record,
            "service": self._service_record(),
        }

    def _service_record(self) -> ServiceRecord:
        last = self.last_error
        return {
            "version": __version__,
            "pid": os.getpid(),
            "host": self.address[0] if self.address else self.config.host,
            "port": self.address[1] if self.address else self.config.port,
            "token_required": self.config.token_required,
            "clients": len(self._clients),
            "uptime_s": round(time.monotonic() - self._started, 3),
            "requests": self.counters["requests"],
            "errors": self.counters["errors"],
            "connections": self.counters["connections"],
            "slow_clients_dropped": self.counters["slow_clients_dropped"],
            "errors_by_code": dict(sorted(self.errors_by_code.items())),
            "last_error": None
            if last is None
            else {
                "code": last[0],
                "message": last[1],
                "age_s": round(time.monotonic() - last[2], 1),
            },
        }

    def status_reply(self) -> dict[str, Any]:
        """The `status` reply, from the snapshot (no device call): for the PLC face."""
        ctx = Context(self.cell, threading.Event(), self.service_status)
        return dict(HANDLERS["status"](ctx, None))

    def call_from_thread(self, cmd: str, wait_s: float) -> dict[str, Any] | None:
        """Hand `cmd` (no arguments) to the dispatcher from another thread (the PLC face's), as
        a JSON request would come; its reply, or None when it still runs after `wait_s` (an
        accepted job)."""
        loop = self._loop
        if loop is None:
            raise OmnisortError(f"{cmd}: the service is not running")
        line = json.dumps({"id": f"plc-{cmd}", "cmd": cmd}).encode()
        try:
            req = proto.parse_request(line, lambda *_a: None)
            return asyncio.run_coroutine_threadsafe(self.dispatch(req), loop).result(wait_s)
        except FutureTimeout:
            return None
        except proto.ProtocolError as exc:  # refused before it started (busy, fault)
            return proto.reply_for(exc)

    # -- life cycle ------------------------------------------------------------------------

    async def start(self) -> tuple[str, int]:
        """Bind the listening socket; returns the (host, port) actually bound."""
        self._loop = asyncio.get_running_loop()
        self._stop_requested = asyncio.Event()
        self._server = await asyncio.start_server(
            self._client,
            host=self.config.host,
            port=self.config.port,
            limit=READ_CHUNK,
            reuse_address=True,
        )
        sock = self._server.sockets[0].getsockname()
        self.address = (str(sock[0]), int(sock[1]))
        log.info("listening on %s:%d", *self.address)
        return self.address

    def request_shutdown(self, reason: str) -> None:
        """Ask the main loop to stop (thread-safe; SIGTERM, SIGINT and `shutdown` call it)."""
        loop, ev = self._loop, self._stop_requested
        if loop is None or ev is None:
            return
        self._stop_reason = self._stop_reason or reason
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(ev.set)

    async def run(self, install_signals: bool = True) -> int:
        """Serve until shutdown is requested, then stop cleanly; returns the exit code (0)."""
        if self._server is None:
            await self.start()
        assert self._stop_requested is not None and self._loop is not None
        if install_signals:
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._loop.add_signal_handler(sig, self.request_shutdown, sig.name)
        host, port = self.address or ("?", 0)
        self.notifier.ready(f"idle; listening on {host}:{port}")
        self.cell.runlog.event("service/state", f"ready on {host}:{port}")
        tasks = [
            asyncio.create_task(self._watchdog_pings()),
            asyncio.create_task(self._log_checks()),
        ]
        try:
            await self._stop_requested.wait()
        finally:
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, *filter(None, [self._roll]), return_exceptions=True)
            if install_signals:
                for sig in (signal.SIGTERM, signal.SIGINT):
                    self._loop.remove_signal_handler(sig)
            await self._shutdown()
        return 0

    async def _watchdog_pings(self) -> None:
        """WATCHDOG=1 from the event loop and nothing else: a ping means the loop is alive."""
        interval = self.notifier.watchdog_interval_s
        if not interval:
            return
        while True:
            self.notifier.watchdog()
            await asyncio.sleep(interval)

    async def _log_checks(self) -> None:
        """Roll the run log by size (during jobs too) and notice a deleted or replaced log
        directory; a failure is reported by the rotator and never ends this loop."""
        last_problem: str | None = None
        while True:
            await asyncio.sleep(self.log_check_s)
            try:
                # shielded: a cancel at shutdown waits for the roll (run's finally) instead
                # of leaving it running while the cell closes
                self._roll = asyncio.ensure_future(asyncio.to_thread(self.cell.roll_runlog))
                await asyncio.shield(self._roll)
                problem = self.cell.log_health().get("problem")
            except Exception as exc:
                problem = f"run log check failed: {exc}"
                log.error("%s", problem)
            if problem != last_problem:
                self.notifier.status(f"run log: {problem}" if problem else "run log ok")
                last_problem = problem

    async def _shutdown(self) -> None:
        reason = self._stop_reason or "shutdown"
        log.info("stopping: %s", reason)
        self.notifier.stopping(f"stopping: {reason}")
        if self._server is not None:
            self._server.close()
        job = self._job
        if job is not None:
            job.cancel.set()
            job.stopped_by = reason
        await asyncio.to_thread(self.cell.stop_motion)
        deadline = time.monotonic() + self.config.shutdown_timeout_s
        while self._job is not None and time.monotonic() < deadline:
            # A job between its cancel check and the start of its motion may still start one:
            # keep stopping the arm until the job has ended.
            await asyncio.sleep(0.1)
            if self._job is not None:
                await asyncio.to_thread(self.cell.stop_motion)
        if self._job is not None:
            log.error(
                "job %s did not end within %.1f s", self._job.cmd, self.config.shutdown_timeout_s
            )
        for w in list(self._clients):
            w.close()
        self.states.set(State.STOPPED, f"service stopping: {reason}")
        self.exit_problems = await asyncio.to_thread(self.cell.close)
        self._quick.shutdown()
        self._safety.shutdown()
        log.info("stopped cleanly")

    def _authorize(self, spec: proto.Command, token: str | None, rid: int | str | None) -> None:
        """Commands that move, write or change state need the token when one is required."""
        if not (self.config.token_required and spec.needs_token):
            return
        if token is None:
            raise proto.ProtocolError(
                proto.UNAUTHORIZED,
                f"{spec.name} needs the service token (field 'token'); only "
                f"{', '.join(proto.OPEN_COMMANDS)} pass without it",
                id=rid,
            )
        expected = (self.config.token or "").encode()
        if not expected or not hmac.compare_digest(token.encode(), expected):
            raise proto.ProtocolError(proto.UNAUTHORIZED, "wrong token", id=rid)

    # -- dispatch --------------------------------------------------------------------------

    async def dispatch(self, req: proto.Request, emit: Emit | None = None) -> dict[str, Any]:
        """Run one validated, authorised request and build its reply; `emit` (in the loop
        thread) gets a job's progress events when the client asked for them."""
        spec = req.command
        if spec.kind == "job":
            return await self._run_job(req, emit)
        if spec.kind == "safety":
            stop = self._stop if req.cmd == "stop" else self._estop
            return await self._in_pool(
                self._safety, req, lambda: to_wire(stop()), self.config.quick_timeout_s
            )
        if req.cmd == "reset":
            empty = bool(req.args.get("gripper_empty"))
            return await self._in_pool(
                self._quick, req, lambda: to_wire(self._reset(empty)), self.config.quick_timeout_s
            )
        if req.cmd == "shutdown":
            self.request_shutdown(f"shutdown requested (request {req.id})")
            return proto.ok_reply(req.id, to_wire(ShutdownReply(shutting_down=True)))
        if req.cmd in ("status", "describe"):
            # Answered in the event loop from the cell's snapshot: no device, no pool.
            ctx = Context(self.cell, threading.Event(), self.service_status)
            return proto.ok_reply(req.id, HANDLERS[req.cmd](ctx, None))
        switches_laser = req.args.get("laser" if req.cmd == "capture" else "on")
        if req.cmd in ("laser", "capture") and switches_laser is not None:
            if self._job is not None:
                raise proto.ProtocolError(
                    proto.BUSY, f"laser is in use by the running {self._job.cmd}; send stop first"
                )
            if switches_laser:
                self._check_may_actuate()
        handler = HANDLERS[req.cmd]
        ctx = Context(self.cell, threading.Event(), self.service_status)
        return await self._in_pool(
            self._quick, req, lambda: handler(ctx, req.payload), self.config.quick_timeout_s
        )

    async def _in_pool(
        self, pool: DaemonPool, req: proto.Request, fn: Callable[[], Reply], timeout: float
    ) -> dict[str, Any]:
        if pool is self._safety:
            # The reply to stop/estop never waits for the status refresh's device reads.
            def then_queue_refresh() -> Reply:
                try:
                    return fn()
                finally:
                    self._quick.submit(lambda: self._then_refresh(lambda: {}))

            fut = asyncio.wrap_future(pool.submit(then_queue_refresh))
        else:
            fut = asyncio.wrap_future(pool.submit(lambda: self._then_refresh(fn)))
        try:
            result = await asyncio.wait_for(fut, timeout)
        except TimeoutError:
            return proto.error_reply(
                req.id,
                proto.DEVICE_ERROR,
                f"{req.cmd} did not finish within {timeout:g} s",
                device_code="device_timeout",
            )
        except Exception as exc:
            code, msg, details = error_from_exception(exc)
            return proto.error_reply(req.id, code, msg, **details)
        return proto.ok_reply(req.id, result)

    def _then_refresh(self, fn: Callable[[], R]) -> R:
        """Run `fn`, then refresh the status snapshot so that the next `status` shows its effect
        (a new calibration, the laser state) whether it succeeded or failed."""
        try:
            return fn()
        finally:
            try:
                self.cell.refresh_status()
            except Exception as exc:
                log.warning("status refresh failed: %s", exc)

    def _check_may_actuate(self) -> None:
        """The state rule of every command that switches something on: none in `fault`."""
        if self.states.state == State.FAULT:
            raise MotionRefusedError(
                f"refused: the cell is in fault ({self.states.reason}); clear the cause and "
                "send reset"
            )


@dataclass
class RunningService:
    """A service running in a background thread (tests and benchmarks)."""

    service: Service
    thread: threading.Thread
    loop: asyncio.AbstractEventLoop
    host: str
    port: int
    exit_code: list[int]

    def stop(self, timeout_s: float = 20.0) -> int | None:
        self.service.request_shutdown("stopped by the test harness")
        self.thread.join(timeout_s)
        return self.exit_code[0] if self.exit_code else None


def start_in_thread(service: Service, timeout_s: float = 10.0) -> RunningService:
    """Run `service` on its own event loop in a daemon thread; returns once it listens."""
    ready = threading.Event()
    box: dict[str, Any] = {}
    exit_code: list[int] = []

    def main() -> None:
        loop = asyncio.new_event_loop()
        box["loop"] = loop
        try:
            box["addr"] = loop.run_until_complete(service.start())
        except BaseException as exc:
            box["error"] = exc
            ready.set()
            return
        ready.set()
        exit_code.append(loop.run_until_complete(service.run(install_signals=False)))
        loop.close()

    thread = threading.Thread(target=main, name="omnisort-service", daemon=True)
    thread.start()
    if not ready.wait(timeout_s):
        raise TimeoutError("service did not start listening in time")
    if "error" in box:
        raise box["error"]
    host, port = box["addr"]
    return RunningService(service, thread, box["loop"], host, port, exit_code)
