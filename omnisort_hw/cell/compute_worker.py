"""A worker process for CPU-bound jobs, so the service's process keeps its GIL for the event
loop, the status path and the stop path.

`ComputeWorker.call(fn, *args)` runs a module-level function in one long-lived child process
and returns its result (arguments and result travel pickled over a pipe). The parent never
blocks for long: it waits in short steps and watches, on each, for a cancel, for the child's
death and for the call's time limit. A child that dies (a crash, a kill, running out of
memory) or overruns its limit is ended and reported as `WorkerError` (protocol code
`internal`); the next call starts a fresh child. Cancelling a call ends the child too (the
computation has no side effects: whatever it produces is saved by the caller after it
returns, so nothing is ever half-saved). An exception raised by the function itself is raised
again in the caller, as it was.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from typing import Any, TypeVar

from omnisort_hw.errors import MotionRefusedError, OmnisortError

log = logging.getLogger("omnisort.worker")

T = TypeVar("T")

POLL_S = 0.02
START_TIMEOUT_S = 60.0


class WorkerError(OmnisortError):
    """The compute worker died or hung during a job; a fresh one serves the next job.

    It says nothing about the devices, so it does not put the cell in fault."""

    code = "internal"
    faults_cell = False


def _serve(conn: Connection) -> None:
    """The child's loop: receive (fn, args, kwargs), send ("ok", result) or ("raised", exc)."""
    conn.send(("ready", os.getpid()))
    while True:
        try:
            fn, args, kwargs = conn.recv()
        except (EOFError, OSError):
            return
        try:
            out: tuple[str, Any] = ("ok", fn(*args, **kwargs))
        except BaseException as exc:  # sent back and raised in the parent
            out = ("raised", exc)
        try:
            conn.send(out)
        except Exception as exc:  # an unpicklable result or exception
            conn.send(("raised", WorkerError(f"the worker could not send its result: {exc}")))


class RecordedLog:
    """A run log that records its calls in the worker, to be replayed on the service's run log
    (so a job's images, points and events still land in the run's .rrd)."""

    enabled = True

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[Any, ...], dict[str, Any]]] = []

    def __getattr__(self, name: str) -> Callable[..., None]:
        if name.startswith("_"):
            raise AttributeError(name)

        def record(*args: Any, **kwargs: Any) -> None:
            self.calls.append((name, args, kwargs))

        return record


def _logged(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> Any:
    """fn(*args, log=RecordedLog(), **kwargs) in the worker; returns (result, log calls)."""
    rec = RecordedLog()
    return fn(*args, log=rec, **kwargs), rec.calls


class ComputeWorker:
    """One child process that runs CPU-bound functions for the service (see module doc)."""

    def __init__(self, name: str = "omnisort-compute") -> None:
        self.name = name
        self._ctx = mp.get_context("spawn")  # no fork of a threaded process
        self._proc: Any = None
        self._conn: Connection | None = None
        self._lock = threading.Lock()  # one call at a time
        self.restarts = 0

    @property
    def pid(self) -> int | None:
        """The running child's PID (None before the first call or after a failure)."""
        proc = self._proc
        return proc.pid if proc is not None and proc.is_alive() else None

    def _start(self) -> None:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_serve, args=(child,), name=self.name, daemon=True)
        proc.start()
        child.close()
        deadline = time.monotonic() + START_TIMEOUT_S
        while not parent.poll(POLL_S):
            if not proc.is_alive() or time.monotonic() > deadline:
                proc.kill()
                proc.join(5.0)
                raise WorkerError(f"the compute worker did not start (exit code {proc.exitcode})")
        parent.recv()
        self._proc, self._conn = proc, parent

    def _end(self, failed: bool = False) -> None:
        """End the child; `failed`: it is ended because of a job (counted in `restarts`)."""
        self.restarts += failed
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        if conn is not None:
            conn.close()
        if proc is not None:
            if proc.is_alive():
                proc.kill()
            proc.join(5.0)

    def call(
        self,
        fn: Callable[..., T],
        *args: Any,
        timeout_s: float | None = None,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        """fn(*args, **kwargs) in the worker; raises what fn raised, `WorkerError` when the
        worker dies or overruns `timeout_s`, `MotionRefusedError` when `cancel` is set."""
        if cancel is not None and cancel.is_set():  # before the job: the worker stays
            raise MotionRefusedError(f"{what} cancelled")
        with self._lock:
            if self._proc is None or not self._proc.is_alive():
                if self._proc is not None:
                    self._end()
                self._start()
            assert self._conn is not None and self._proc is not None
            proc, conn = self._proc, self._conn
            try:
                conn.send((fn, args, kwargs))
            except (OSError, ValueError) as exc:
                self._end()
                raise WorkerError(f"{what}: could not hand the job to the worker: {exc}") from None
            deadline = None if timeout_s is None else time.monotonic() + timeout_s
            while True:
                try:
                    ready = conn.poll(POLL_S)
                except (EOFError, OSError):
                    ready = False
                if ready:
                    try:
                        status, value = conn.recv()
                    except (EOFError, OSError):
                        status, value = "died", None
                    if status == "ok":
                        return value
                    if status == "raised":
                        raise value
                if cancel is not None and cancel.is_set():
                    self._end(failed=True)
                    raise MotionRefusedError(f"{what} cancelled")
                if not proc.is_alive() or (ready and status == "died"):
                    self._end(failed=True)
                    code = proc.exitcode
                    log.error("compute worker died during %s (exit code %s)", what, code)
                    raise WorkerError(
                        f"{what}: the compute worker died (exit code {code}); nothing was "
                        "saved, and a fresh worker takes the next job"
                    )
                if deadline is not None and time.monotonic() > deadline:
                    self._end(failed=True)
                    log.error("compute worker hung in %s for %.0f s; ended", what, timeout_s)
                    raise WorkerError(
                        f"{what}: the compute worker did not answer within {timeout_s:g} s and "
                        "was ended; nothing was saved, and a fresh worker takes the next job"
                    )

    def call_logged(
        self,
        fn: Callable[..., T],
        log: Any,
        *args: Any,
        cancel: threading.Event | None = None,
        what: str = "job",
        **kwargs: Any,
    ) -> T:
        """`call` for a function with a `log` keyword: it logs into a recorder in the worker,
        and the calls are replayed on `log` here once the function has returned."""
        result, calls = self.call(_logged, fn, args, kwargs, cancel=cancel, what=what)
        if getattr(log, "enabled", False):
            for name, a, k in calls:
                getattr(log, name)(*a, **k)
        return result

    def close(self) -> None:
        """End the child (waits up to 5 s)."""
        with self._lock:
            self._end()
