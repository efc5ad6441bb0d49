"""The simulated cell in a child process of its own (the "sim host"), with the caller's end.

pybullet's rendering and stepping and the sensor model's exposures hold the GIL of whatever
process runs them. The service must keep answering while they run, so for the service the
simulated world and its devices live in a child process, and the service holds thin proxies
(`sim_backend.device_proxies`) that implement the `drivers.base` interfaces and forward every
call over a pipe. `SimHost` is the caller's end:

- the child is started with "spawn" (no fork of a threaded process) and builds the devices
  with the in-process factory (`sim_backend.devices.open_devices`), so a device behaves as it
  does in process, configuration errors included (raised again in the caller, typed);
- the child serves calls concurrently: a reader thread receives each request and runs it on a
  thread of its own, so `stop()` reaches the arm while a move steps in another thread (the
  stop runs on the reader thread itself, within one physics step of its arrival);
- every call waits with a timeout. A child that dies gives `DeviceDisconnectedError` at once
  (to every call in flight and every later one), a child that does not answer in time
  `DeviceTimeoutError`, both naming the device; a hung child is ended, since nothing it does
  can be observed any more;
- a device connected again after such a loss (the service's `reset`) starts a fresh child, a
  new simulated cell from the same settings (`restart_if_lost`), as a real device comes back
  when it is reconnected;
- `close()` asks the child to close its devices and exit, waits `CLOSE_TIMEOUT_S`, then ends it.

Exceptions travel as their class, message and attributes (a typed error stays typed even when
its constructor takes keyword-only arguments).
"""

from __future__ import annotations

import contextlib
import importlib
import itertools
import logging
import multiprocessing as mp
import os
import threading
import time
import weakref
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from drivers.errors import DeviceDisconnectedError, DeviceError, DeviceTimeoutError

log = logging.getLogger("omnisort.sim_host")

START_TIMEOUT_S = 120.0  # spawning, importing pybullet and building the world
CLOSE_TIMEOUT_S = 5.0
REPLY_MARGIN_S = 10.0  # added to a call's own timeout before the child counts as hung
CALL_TIMEOUT_S = 30.0  # calls without a timeout of their own (reads, clean images, truth)
# Calls the child's reader thread runs itself, at once: they must pass whatever else runs.
INLINE = frozenset({"stop", "trigger_protective_stop"})


# -- exceptions across the pipe ---------------------------------------------------------------


def encode_exception(exc: BaseException) -> tuple[str, str, tuple[Any, ...], dict[str, Any]]:
    """(module, class name, args, attributes) of `exc`, picklable."""
    import pickle

    attrs = {}
    for key, value in vars(exc).items():
        try:
            pickle.dumps(value)
        except Exception:
            continue
        attrs[key] = value
    args = exc.args
    try:
        pickle.dumps(args)
    except Exception:
        args = (str(exc),)
    return type(exc).__module__, type(exc).__qualname__, args, attrs


def decode_exception(encoded: tuple[str, str, tuple[Any, ...], dict[str, Any]]) -> BaseException:
    """The exception `encode_exception` described, rebuilt without calling its constructor."""
    module, name, args, attrs = encoded
    try:
        cls = importlib.import_module(module)
        for part in name.split("."):
            cls = getattr(cls, part)
        if not (isinstance(cls, type) and issubclass(cls, BaseException)):
            raise TypeError(name)
        exc = cls.__new__(cls)
        BaseException.__init__(exc, *args)
        exc.__dict__.update(attrs)
        return exc
    except Exception:
        return DeviceError(f"{name}: {args[0] if args else ''}", device=attrs.get("device"))


# -- the child ----------------------------------------------------------------------------------


def _describe(obj: object) -> dict[str, list[str]]:
    """Public methods and data attributes of `obj`'s class and instance (what a proxy forwards)."""
    methods, attrs = [], []
    for name in dir(obj):
        if name.startswith("_"):
            continue
        static = getattr(type(obj), name, None)
        if isinstance(static, property) or static is None:
            attrs.append(name)
        elif callable(static):
            methods.append(name)
        else:
            attrs.append(name)
    return {"methods": methods, "attrs": attrs}


def _resolve(obj: object, path: str) -> Any:
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


class _Served:
    """The child's side: the devices and the objects calls may address."""

    def __init__(self, conn: Connection, made: dict[str, Any]) -> None:
        from sim_backend.sort_harness import SimVerifier

        self.conn = conn
        self.send_lock = threading.Lock()
        self.targets: dict[str, Any] = dict(made)
        arm = made.get("arm")
        if arm is not None:
            self.targets["gripper"] = arm.gripper
        self.cell = next(d.cell for d in made.values())
        self.targets["cell"] = self.cell
        self._verifier = SimVerifier
        self._ids = itertools.count()
        self._trace: dict[str, Any] | None = None
        self.pool = ThreadPoolExecutor(max_workers=16, thread_name_prefix="simhost")
        self.closed = False

    def hello(self) -> dict[str, Any]:
        kinds = [k for k in ("camera", "laser", "arm") if k in self.targets]
        return {
            "pid": os.getpid(),
            "kinds": kinds,
            "scene": self.cell.scene,
            "cell_name": self.cell.name,
            "names": {k: self.targets[k].name for k in kinds},
            "shapes": {k: _describe(v) for k, v in self.targets.items()},
        }

    def run(self, target: str, op: str, name: str, args: tuple, kwargs: dict) -> Any:
        if op == "verifier":  # a truth monitor of the arm, addressed by the id returned
            key = f"verifier:{next(self._ids)}"
            self.targets[key] = self._verifier(self.targets["arm"])
            return key, _describe(self.targets[key])
        if op == "trace":
            return self.trace()
        obj = self.targets[target]
        if op == "get":
            return _resolve(obj, name)
        if op == "set":
            setattr(obj, name, args[0])
            return None
        if op == "done":  # verifier.on_done mutates the report it is given: send it back
            obj.on_done(*args, **kwargs)
            return args[0]
        return getattr(obj, name)(*args, **kwargs)

    def trace(self) -> dict[str, Any]:
        """The arm time of the last motion sample and of every `stop()`'s arrival, recorded from
        the first call on (what bounds a stop's latency in the arm's own time)."""
        arm, world = self.targets["arm"], self.cell.world
        if self._trace is None:
            rec: dict[str, Any] = {"samples": 0, "last_sample": None, "stops": []}
            set_joints, stop = world.set_joints, arm.stop

            def sample(q: Any) -> None:
                rec["samples"] += 1
                rec["last_sample"] = world.sim_time
                set_joints(q)

            def stopped() -> None:
                rec["stops"].append(world.sim_time)
                stop()

            world.set_joints, arm.stop = sample, stopped
            self._trace = rec
        return {**self._trace, "stops": list(self._trace["stops"]), "now": world.sim_time}

    def reply(self, rid: int, request: tuple) -> None:
        try:
            out: tuple = (rid, "ok", self.run(*request))
        except BaseException as exc:
            out = (rid, "raised", encode_exception(exc))
        with self.send_lock:
            try:
                self.conn.send(out)
            except (OSError, ValueError):
                return
            except Exception as exc:  # an unpicklable result
                self.conn.send((rid, "raised", encode_exception(DeviceError(str(exc)))))

    def close(self) -> None:
        """Stop the arm, close the devices and the cell, once (the "close" request, then the
        serve loop's end)."""
        if self.closed:
            return
        self.closed = True
        arm = self.targets.get("arm")
        if arm is not None:
            arm.stop()  # a move still stepping on a pool thread ends before the process does
        for kind in ("camera", "laser", "arm"):
            dev = self.targets.get(kind)
            if dev is not None:
                try:
                    dev.close()
                except Exception as exc:
                    log.warning("sim host: closing %s: %s", kind, exc)
        self.pool.shutdown(wait=False, cancel_futures=True)
        self.cell.close()


def serve(conn: Connection, sections: dict[str, dict[str, Any]], base_dir: str | None) -> None:
    """The child's main: build the devices, say hello, serve calls until "close" or EOF."""
    import sys

    from sim_backend.devices import open_devices

    sys.setswitchinterval(0.001)  # the reader thread (stop) gets the GIL quickly
    try:
        made = open_devices(sections, Path(base_dir) if base_dir else None)
        served = _Served(conn, made)
        conn.send(("ready", served.hello()))
    except BaseException as exc:
        conn.send(("failed", encode_exception(exc)))
        return
    try:
        while True:
            try:
                rid, request = conn.recv()
            except (EOFError, OSError):
                break
            if request == "close":
                served.close()
                with served.send_lock:
                    conn.send((rid, "ok", None))
                return
            if request[2] in INLINE:
                served.reply(rid, request)
            else:
                served.pool.submit(served.reply, rid, request)
    finally:
        served.close()


# -- the caller's end ---------------------------------------------------------------------------


class _Pending:
    __slots__ = ("event", "outcome")

    def __init__(self) -> None:
        self.event = threading.Event()
        self.outcome: tuple[str, Any] | None = None


class SimHost:
    """One child process holding one simulated cell; calls go through `call` (see module doc)."""

    def __init__(
        self,
        sections: dict[str, dict[str, Any]],
        base_dir: Path | None,
        call_timeout_s: float = CALL_TIMEOUT_S,
        reply_margin_s: float = REPLY_MARGIN_S,
    ) -> None:
        self.call_timeout_s = float(call_timeout_s)
        self.reply_margin_s = float(reply_margin_s)
        self._spawn_args = (sections, str(base_dir) if base_dir else None)
        self._send_lock = threading.Lock()
        self._pending: dict[int, _Pending] = {}
        self._pending_lock = threading.Lock()
        self._life_lock = threading.Lock()
        self._ids = itertools.count()
        self._closed = False
        self.users = 0  # proxies that have not been closed yet
        self.starts = 0  # child processes started (1 + the fresh ones after a loss)
        self._start()

    def _start(self) -> None:
        """Spawn a child, wait for its devices, and read its replies from now on."""
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=serve, args=(child, *self._spawn_args), name="omnisort-sim-host", daemon=True
        )
        self._proc.start()
        child.close()
        self._conn = parent
        self._dead: str | None = None  # why calls can no longer be made
        hello = self._await_hello()
        self.pid: int = hello["pid"]
        self.kinds: list[str] = hello["kinds"]
        self.scene = hello["scene"]
        self.cell_name: str = hello["cell_name"]
        self.names: dict[str, str] = hello["names"]
        self.shapes: dict[str, dict[str, list[str]]] = hello["shapes"]
        self._reader = threading.Thread(
            target=self._read, args=(self._conn, self._proc), name="simhost-reader", daemon=True
        )
        self._reader.start()
        self._finalizer = weakref.finalize(self, _end_process, self._proc, self._conn)
        self.starts += 1

    def restart_if_lost(self) -> bool:
        """A fresh child (a new simulated cell from the same settings) in place of one that
        died or hung, as a real device comes back when it is connected again; True if one was
        started. Calls in flight at the loss have had their typed error already."""
        with self._life_lock:
            if self._dead is None or self._closed:
                return False
            lost = self._dead
            self._finalizer()
            self._reader.join(CLOSE_TIMEOUT_S)
            self._start()
        log.warning("sim host: a fresh simulated cell (pid %d) after: %s", self.pid, lost)
        return True

    def _await_hello(self) -> dict[str, Any]:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self._conn.poll(0.05):
            if not self._proc.is_alive() or time.monotonic() > deadline:
                _end_process(self._proc, self._conn)
                raise DeviceTimeoutError(
                    f"the simulated cell's process did not start within {START_TIMEOUT_S:g} s "
                    f"(exit code {self._proc.exitcode})",
                    device="sim",
                )
        try:
            status, value = self._conn.recv()
        except (EOFError, OSError):
            status, value = "died", None
        if status != "ready":
            _end_process(self._proc, self._conn)
            if status == "failed":
                raise decode_exception(value)
            raise DeviceDisconnectedError(
                f"the simulated cell's process ended while starting (exit code "
                f"{self._proc.exitcode})",
                device="sim",
            )
        return value

    @property
    def alive(self) -> bool:
        return self._dead is None and self._proc.is_alive()

    @property
    def process(self) -> Any:
        """The child's `multiprocessing.Process` (its pid, exit code)."""
        return self._proc

    def _read(self, conn: Connection, proc: Any) -> None:
        while True:
            try:
                rid, status, value = conn.recv()
            except (EOFError, OSError, ValueError):
                break
            with self._pending_lock:
                waiter = self._pending.pop(rid, None)
            if waiter is not None:
                waiter.outcome = (status, value)
                waiter.event.set()
        proc.join(1.0)
        if conn is self._conn:  # not a child replaced by a fresh one meanwhile
            self._fail_all(f"the simulated cell's process ended (exit code {proc.exitcode})")

    def _fail_all(self, why: str) -> None:
        if self._dead is None:
            self._dead = why
            if self.users:
                log.error("sim host: %s", why)
        with self._pending_lock:
            waiting, self._pending = list(self._pending.values()), {}
        for waiter in waiting:
            waiter.event.set()

    def call(
        self,
        device: str,
        target: str,
        op: str,
        name: str = "",
        args: tuple[Any, ...] = (),
        kwargs: dict[str, Any] | None = None,
        timeout_s: float | None = None,
    ) -> Any:
        """Run `op` ("call", "get", "set", ...) of `name` on `target` in the child and return
        its result; raises what it raised, or a typed error naming `device`. `timeout_s`
        defaults to `call_timeout_s`."""
        timeout_s = self.call_timeout_s if timeout_s is None else timeout_s
        if self._dead is not None:
            raise DeviceDisconnectedError(f"{device}: {self._dead}", device=device)
        rid = next(self._ids)
        waiter = _Pending()
        with self._pending_lock:
            self._pending[rid] = waiter
        try:
            with self._send_lock:
                self._conn.send((rid, (target, op, name, tuple(args), dict(kwargs or {}))))
        except (OSError, ValueError) as exc:
            with self._pending_lock:
                self._pending.pop(rid, None)
            self._fail_all(f"the simulated cell's process cannot be reached ({exc})")
            raise DeviceDisconnectedError(f"{device}: {self._dead}", device=device) from None
        if not waiter.event.wait(timeout_s):
            with self._pending_lock:
                self._pending.pop(rid, None)
            what = f"{name or op}"
            self._hung(f"{device}: {what} had no answer from the simulated cell's process")
            raise DeviceTimeoutError(
                f"{device}: {what} had no answer within {timeout_s:.1f} s; the simulated "
                "cell's process was ended",
                device=device,
            )
        if waiter.outcome is None:
            raise DeviceDisconnectedError(f"{device}: {self._dead}", device=device)
        status, value = waiter.outcome
        if status == "raised":
            raise decode_exception(value)
        return value

    def _hung(self, why: str) -> None:
        log.error("sim host: %s; ending it", why)
        _end_process(self._proc, None)
        self._fail_all(why)

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
        """Close the devices in the child and end it (within `timeout_s`, then by force)."""
        if self._dead is None and self._proc.is_alive():
            rid = next(self._ids)
            waiter = _Pending()
            with self._pending_lock:
                self._pending[rid] = waiter
            with contextlib.suppress(OSError, ValueError):
                with self._send_lock:
                    self._conn.send((rid, "close"))
                waiter.event.wait(timeout_s)
            self._proc.join(timeout_s)
        self._closed = True
        self._dead = self._dead or "the simulated cell's process was closed"
        self._finalizer()
        self._reader.join(timeout_s)


def _end_process(proc: Any, conn: Connection | None) -> None:
    """End the child now if it still runs, and reap it."""
    if proc.is_alive():
        proc.kill()
    proc.join(CLOSE_TIMEOUT_S)
    if conn is not None:
        conn.close()
