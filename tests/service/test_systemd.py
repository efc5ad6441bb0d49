"""sd_notify against real datagram sockets, and SIGTERM of the service in a subprocess."""

from __future__ import annotations

import os
import signal
import socket
import time
import uuid
from pathlib import Path

import pytest

from omnisort_hw.runlog import entity_paths
from omnisort_hw.service.client import Client
from omnisort_hw.service.systemd import Notifier
from tests.service.procs import start_service

pytestmark = pytest.mark.timeout(60)


def _receiver(address: str | bytes) -> socket.socket:
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(address)
    sock.settimeout(5)
    return sock


def test_notify_over_a_filesystem_socket(tmp_path: Path) -> None:
    path = str(tmp_path / "notify.sock")
    with _receiver(path) as rx:
        n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "3000000"})
        assert n.enabled and n.watchdog_interval_s == pytest.approx(1.5)
        assert n.ready("listening on 127.0.0.1:1")
        msg = rx.recv(4096).decode()
        assert msg.splitlines() == [
            "READY=1",
            f"MAINPID={os.getpid()}",
            "STATUS=listening on 127.0.0.1:1",
        ]
        assert n.watchdog()
        assert rx.recv(4096) == b"WATCHDOG=1"
        assert n.status("sorting:\nline two")
        assert rx.recv(4096) == b"STATUS=sorting: line two"
        assert n.stopping()
        assert rx.recv(4096) == b"STOPPING=1"
        n.close()


def test_notify_over_an_abstract_socket() -> None:
    name = f"omnisort-test-{uuid.uuid4().hex}"
    with _receiver(b"\0" + name.encode()) as rx:
        n = Notifier({"NOTIFY_SOCKET": "@" + name})
        assert n.watchdog() is False  # no WATCHDOG_USEC: nothing to ping
        assert n.status("x")
        assert rx.recv(4096) == b"STATUS=x"
        n.close()


def test_a_receiver_that_stops_reading_never_blocks_the_sender(tmp_path: Path) -> None:
    """The event loop pings from the main thread: a full notify queue must drop, not block."""
    path = str(tmp_path / "full.sock")
    with _receiver(path):
        n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "1000000"})
        t0 = time.monotonic()
        results = [n.watchdog() for _ in range(5000)]
        assert time.monotonic() - t0 < 5.0
        assert results[0] is True and results[-1] is False
        n.close()


def test_no_op_outside_systemd() -> None:
    n = Notifier({})
    assert not n.enabled and n.watchdog_interval_s is None
    assert n.ready() is False and n.watchdog() is False
    other = Notifier(
        {"NOTIFY_SOCKET": "/nonexistent/sock", "WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "1"}
    )
    assert other.watchdog_interval_s is None
    assert other.watchdog() is False


def test_sigterm_during_a_motion_exits_cleanly(tmp_path: Path) -> None:
    """READY once up, WATCHDOG pings, then SIGTERM: arm stopped, laser off, log flushed, 0."""
    sock_path = str(tmp_path / "notify.sock")
    rx = _receiver(sock_path)
    proc, host, port = start_service(
        tmp_path,
        "--move-seconds",
        "30",
        env={"NOTIFY_SOCKET": sock_path, "WATCHDOG_USEC": "400000"},
    )
    try:
        got: list[str] = []
        deadline = time.monotonic() + 10
        while "WATCHDOG=1" not in got and time.monotonic() < deadline:
            got += rx.recv(4096).decode().splitlines()
        assert "READY=1" in got and "WATCHDOG=1" in got
        assert got.index("READY=1") < got.index("WATCHDOG=1")
        with Client(host, port) as c:
            assert c.call("laser", {"on": True})["ok"]
            c.send("move", {"joints_deg": [20, 0, 0, 0, 0, 0]})
            journal_path = tmp_path / "state" / "journal.txt"
            deadline = time.monotonic() + 10
            while "arm move_joints start" not in journal_path.read_text():
                assert time.monotonic() < deadline, "the move did not start"
                time.sleep(0.02)
            assert c.call("status")["result"]["state"] == "moving"
            proc.send_signal(signal.SIGTERM)
            rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    assert rc == 0
    rx.settimeout(0.5)
    with pytest.raises(TimeoutError):
        while True:
            got += rx.recv(4096).decode().splitlines()
    rx.close()
    assert "STOPPING=1" in got
    journal = (tmp_path / "state" / "journal.txt").read_text().splitlines()
    assert "arm move_joints interrupted" in journal
    assert "arm stop" in journal[journal.index("arm move_joints start") :]
    last_on = max(i for i, e in enumerate(journal) if e == "laser on")
    assert "laser off" in journal[last_on:]
    assert {"arm close", "laser close", "camera close"} <= set(journal)
    rrds = list((tmp_path / "logs").glob("*.rrd"))
    assert len(rrds) == 1
    paths = entity_paths(rrds[0])
    assert {"/service/state", "/arm/command", "/laser/state", "/service/devices"} <= paths
    stderr = (tmp_path / "stderr.txt").read_text()
    assert "stopped cleanly" in stderr and "Traceback" not in stderr
