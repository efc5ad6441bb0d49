"""ur-rtde in a worker process, so that no ur-rtde call can hang the service.

ur-rtde's constructors hold the GIL while they block, and neither they nor the control
interface's command handshake have a timeout a caller can set: a controller that accepts and
then stops answering freezes every thread of the process that made the call. `RTDEWorker`
keeps the three interfaces (receive, control, IO) in a child process and sends it one request
at a time over a pipe; each request waits at most its timeout, after which the child is
killed and the caller gets `DeviceTimeoutError`. A child that dies (ur-rtde aborts the process
when the controller vanishes mid-read) gives `DeviceDisconnectedError`.

The child also watches the controller's clock (RTDE `timestamp`): state older than
`state_timeout_s` is refused as stale, which is how a stalled controller is told from a slow
one long before ur-rtde's own 2.5 s receive deadline drops the connection.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from drivers.errors import DeviceDisconnectedError, DeviceError, DeviceTimeoutError

_ROOT = str(Path(__file__).resolve().parents[1])
ROBOT_MODE_RUNNING = 7  # RTDE robot_mode RUNNING
SAFETY_MODE_NORMAL = 1  # RTDE safety_mode NORMAL
_IO_BIT_OFFSET = {"standard": 0, "configurable": 8, "tool": 16}
_SETTERS = {
    "tool": "setToolDigitalOut",
    "standard": "setStandardDigitalOut",
    "configurable": "setConfigurableDigitalOut",
}


class _LostError(Exception):
    """The connection was lost and re-established under a command."""


class _StaleError(Exception):
    """The controller's clock did not advance within state_timeout_s."""


class _Session:
    """The ur-rtde interfaces of one controller, inside the worker process."""

    def __init__(self, host: str, state_timeout_s: float) -> None:
        import rtde_control
        import rtde_io
        import rtde_receive

        self.rcv = rtde_receive.RTDEReceiveInterface(host)
        self.ctl = rtde_control.RTDEControlInterface(host)
        self.io = rtde_io.RTDEIOInterface(host)
        self.state_timeout_s = state_timeout_s
        self._stamp = -1.0
        self._seen = time.monotonic()

    def fresh(self) -> None:
        stamp = self.rcv.getTimestamp()
        now = time.monotonic()
        if stamp != self._stamp:
            self._stamp, self._seen = stamp, now
        elif now - self._seen > self.state_timeout_s:
            raise _StaleError(f"controller state not updated for {now - self._seen:.2f} s")

    def is_connected(self) -> bool:
        return bool(self.rcv.isConnected() and self.ctl.isConnected() and self.io.isConnected())

    def ensure_program(self) -> None:
        """(Re)start ur-rtde's control script if it is not running (after a protective stop
        was unlocked, or a dashboard stop). Only the caller's new command follows."""
        if self.ctl.isProgramRunning():
            return
        if not self.ctl.reuploadScript():
            raise RuntimeError("could not re-upload the RTDE control script")
        deadline = time.monotonic() + 2.0
        while not self.ctl.isProgramRunning():
            if time.monotonic() > deadline:
                raise RuntimeError("the RTDE control script did not start within 2 s")
            time.sleep(0.005)

    def script_lost(self) -> bool:
        """Why a command was refused with safety NORMAL: the control script stopped, or the
        controller is RUNNING and so would have taken it, which leaves only a script that
        was not there (ur-rtde's isProgramRunning can still report the state from before a
        dropped connection it re-established). Any other refusal is the controller's."""
        if self.rcv.getSafetyMode() != SAFETY_MODE_NORMAL:
            return False
        return not self.ctl.isProgramRunning() or self.rcv.getRobotMode() == ROBOT_MODE_RUNNING

    def call(self, name: str, args: tuple) -> Any:
        rcv, ctl, io = self.rcv, self.ctl, self.io
        if name == "is_connected":
            return self.is_connected()
        if name == "close":
            with contextlib.suppress(RuntimeError):
                ctl.stopScript()
            return None
        if name == "reconnect":
            return bool(rcv.reconnect() and ctl.reconnect() and io.reconnect())
        if name in ("stop_j", "stop_l"):
            (getattr(ctl, "stopJ" if name == "stop_j" else "stopL"))(*args)
            return None
        self.fresh()
        if name == "actual_q":
            return list(rcv.getActualQ())
        if name == "actual_qd":
            return list(rcv.getActualQd())
        if name == "actual_tcp_pose":
            return list(rcv.getActualTCPPose())
        if name == "modes":
            return int(rcv.getRobotMode()), int(rcv.getSafetyMode())
        if name == "timestamp":
            return float(rcv.getTimestamp())
        if name in ("move_j", "move_l"):
            self.ensure_program()
            fn = ctl.moveJ if name == "move_j" else ctl.moveL
            accepted = bool(fn(list(args[0]), float(args[1]), float(args[2]), True))
            if not accepted and self.script_lost():
                raise _LostError(
                    "the control script was not there to take the command (ur-rtde "
                    "re-established a dropped connection); the command was not carried out"
                )
            return accepted
        if name == "move_path":
            self.ensure_program()
            accepted = bool(ctl.movePath(_ur_path(args[0]), True))
            if not accepted and self.script_lost():
                raise _LostError("the control script stopped during the path; nothing carried out")
            return accepted
        if name == "is_moving":
            return bool(ctl.getAsyncOperationProgressEx().isAsyncOperationRunning())
        if name == "set_output":
            kind, pin, value = args
            return bool(getattr(io, _SETTERS[kind])(int(pin), bool(value)))
        if name in ("output", "input"):
            kind, pin = args
            bits = (
                rcv.getActualDigitalOutputBits()
                if name == "output"
                else (rcv.getActualDigitalInputBits())
            )
            return bool((int(bits) >> (_IO_BIT_OFFSET[kind] + int(pin))) & 1)
        raise ValueError(f"unknown worker request {name!r}")


def _ur_path(rows: list[tuple[str, list[float]]]) -> Any:
    """ur-rtde's Path of (kind, [6 values, speed, acceleration, blend]) rows: a movej to joints
    or a movel to a pose each (sent as the control script with the path injected, then the
    path command: ur-rtde's `movePath`)."""
    from rtde_control import Path as URPath
    from rtde_control import PathEntry

    path = URPath()
    for kind, row in rows:
        if kind == "linear":
            entry = PathEntry(PathEntry.MoveL, PathEntry.PositionTcpPose, list(row))
        else:
            entry = PathEntry(PathEntry.MoveJ, PathEntry.PositionJoints, list(row))
        path.addEntry(entry)
    return path


def _quiet_disconnect(iface: Any) -> None:
    with contextlib.suppress(RuntimeError):
        iface.disconnect()


def _worker_main(conn: Any, host: str, state_timeout_s: float) -> None:
    """Child process: connect, then answer requests until told to stop or the pipe closes."""
    try:
        session = _Session(host, state_timeout_s)
    except (RuntimeError, ValueError) as exc:
        conn.send(("error", "refused", str(exc)))
        return
    conn.send(("ok", None))
    while True:
        try:
            name, args = conn.recv()
        except (EOFError, OSError):
            return
        try:
            conn.send(("ok", session.call(name, args)))
        except _StaleError as exc:
            conn.send(("error", "stale", str(exc)))
        except _LostError as exc:
            conn.send(("error", "disconnected", str(exc)))
        except RuntimeError as exc:
            kind = "disconnected" if not session.is_connected() else "runtime"
            conn.send(("error", kind, str(exc)))
        except ValueError as exc:
            # ur-rtde's own range checks (a speed above its 3.14 rad/s, ...): the request is
            # refused, the session goes on (uncaught, it ended the worker: "connection lost").
            conn.send(("error", "runtime", str(exc)))
        if name == "close":
            # the caller has its answer; ur-rtde's disconnects sleep 0.5 s each (GIL released)
            threads = [
                threading.Thread(target=_quiet_disconnect, args=(i,))
                for i in (session.ctl, session.io, session.rcv)
            ]
            for t in threads:
                t.start()
            for t in threads:
                t.join(5.0)
            return


class RTDEWorker:
    """A child process holding ur-rtde's interfaces to `host`; calls with timeouts."""

    def __init__(self, host: str, state_timeout_s: float = 0.5) -> None:
        self.host = host
        self.state_timeout_s = state_timeout_s
        self._conn: Any = None
        self._proc: Any = None
        self._lock = threading.Lock()  # one request and its reply at a time

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def start(self, timeout_s: float) -> None:
        """Start the child (`python -m drivers.ur_rtde_worker`, not multiprocessing's spawn,
        which would re-import the caller's main module) and wait for it to connect."""
        parent, child = socket.socketpair()
        try:
            self._proc = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "drivers.ur_rtde_worker",
                    str(child.fileno()),
                    self.host,
                    str(self.state_timeout_s),
                ],
                pass_fds=(child.fileno(),),
                stdin=subprocess.DEVNULL,
                cwd=_ROOT,
                env={**os.environ, "PYTHONPATH": _pythonpath()},
            )
        finally:
            child.close()
        self._conn = Connection(parent.detach())
        self._receive("connect", timeout_s)

    def call(self, name: str, *args: Any, timeout_s: float) -> Any:
        """Run one request in the child; thread-safe (requests from several threads queue)."""
        deadline = time.monotonic() + timeout_s
        if not self._lock.acquire(timeout=timeout_s):
            raise DeviceTimeoutError(
                f"UR controller at {self.host}: {name} waited {timeout_s:.1f} s for another "
                "request to finish",
                device=self.host,
            )
        try:
            return self._call(name, args, max(0.0, deadline - time.monotonic()))
        finally:
            self._lock.release()

    def _call(self, name: str, args: tuple, timeout_s: float) -> Any:
        if not self.alive:
            raise DeviceDisconnectedError(
                f"UR controller at {self.host}: not connected", device=self.host
            )
        try:
            self._conn.send((name, args))
        except (OSError, BrokenPipeError):
            self.kill()
            raise DeviceDisconnectedError(
                f"UR controller at {self.host}: the ur-rtde worker is gone during {name}",
                device=self.host,
            ) from None
        return self._receive(name, timeout_s)

    def _receive(self, what: str, timeout_s: float) -> Any:
        try:
            ready = self._conn.poll(timeout_s)
        except (OSError, EOFError):
            ready = True
        if not ready:
            self.kill()
            raise DeviceTimeoutError(
                f"UR controller at {self.host}: no answer to {what} within {timeout_s:.1f} s "
                "(controller stalled or network down); the connection was dropped",
                device=self.host,
            )
        try:
            reply = self._conn.recv()
        except (EOFError, OSError):
            self.kill()
            raise DeviceDisconnectedError(
                f"UR controller at {self.host}: connection lost during {what}",
                device=self.host,
            ) from None
        if reply[0] == "ok":
            return reply[1]
        _, kind, message = reply
        if kind == "stale":
            raise DeviceTimeoutError(
                f"UR controller at {self.host}: {message} during {what} (controller stalled?)",
                device=self.host,
            )
        if kind == "disconnected":
            raise DeviceDisconnectedError(
                f"UR controller at {self.host}: connection lost during {what} ({message})",
                device=self.host,
            )
        if kind == "refused":
            self.kill()
            raise DeviceError(
                f"UR controller at {self.host} refused the RTDE connection ({message}): put the "
                "robot in Remote Control mode and make sure no other program holds the RTDE "
                "control interface",
                device=self.host,
            )
        raise DeviceError(
            f"UR controller at {self.host}: {what} failed: {message}", device=self.host
        )

    def kill(self) -> None:
        """End the child now (it may be stuck inside ur-rtde)."""
        proc, self._proc = self._proc, None
        if self._conn is not None:
            with contextlib.suppress(OSError):
                self._conn.close()
            self._conn = None
        if proc is not None:
            if proc.poll() is None:
                proc.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(2.0)

    def close(self, timeout_s: float = 3.0) -> None:
        """Disconnect cleanly if the child answers in time; kill it otherwise."""
        if self.alive:
            with contextlib.suppress(DeviceError):
                self.call("close", timeout_s=timeout_s)
            proc, self._proc = self._proc, None
            if proc is not None:  # it disconnects and exits by itself; reap it meanwhile
                threading.Thread(target=_reap, args=(proc, timeout_s + 5.0), daemon=True).start()
        self.kill()


def _reap(proc: subprocess.Popen[bytes], timeout_s: float) -> None:
    try:
        proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _pythonpath() -> str:
    extra = os.environ.get("PYTHONPATH", "")
    return _ROOT + (os.pathsep + extra if extra else "")


def main(argv: list[str]) -> int:
    """Child entry point: `python -m drivers.ur_rtde_worker FD HOST STATE_TIMEOUT_S`."""
    conn = Connection(int(argv[0]))
    _worker_main(conn, argv[1], float(argv[2]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
