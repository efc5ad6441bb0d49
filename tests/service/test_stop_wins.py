"""Stop always wins: stop/estop are served whatever the connections held, idle connections and
unfinished lines time out, and one address cannot take every slot.

Latency bounds are derived from the latency of the same call measured on the same service
before the load (so a slow machine does not fail them); the issue's 50 ms figure is the floor
of that bound and the measured numbers go to `benchmarks/bench_faults.py`.
"""

from __future__ import annotations

import json
import socket
import statistics
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from omnisort_hw.service.loadgen import idle_connections, round_trip
from tests.service.conftest import Harness

pytestmark = pytest.mark.timeout(120)

ISSUE_BOUND_S = 0.050
# The held load may cost at most this many times the unloaded round trip (scheduling noise of
# a loaded 2-core machine); the bound is never below the issue's 50 ms.
LOAD_FACTOR = 10.0


def _baseline_s(h: Harness, n: int = 7) -> float:
    return statistics.median(
        round_trip(h.running.host, h.running.port, "status")[1] for _ in range(n)
    )


@contextmanager
def _held(h: Harness, n: int, sources: list[str]) -> Iterator[list[socket.socket]]:
    """`n` idle connections spread over `sources`, all accepted by the service."""
    before = h.running.service.counters["connections"]
    with idle_connections(h.running.host, h.running.port, n, sources) as socks:
        deadline = time.monotonic() + 10
        while h.running.service.counters["connections"] < before + n:
            assert time.monotonic() < deadline, "the service did not accept every connection"
            time.sleep(0.01)
        yield socks


def _wait_moving(h: Harness) -> None:
    deadline = time.monotonic() + 5
    while not h.devices.arm.moving.is_set():
        assert time.monotonic() < deadline, "the move did not start"
        time.sleep(0.005)


def test_estop_served_with_200_idle_connections_held(make_service) -> None:
    # Default limits (64 clients, 16 per address): 64 connections are clients, the other 136
    # wait for their first line; none of them sends anything.
    h = make_service(move_seconds=5.0, overflow_grace_s=30.0)
    bound = max(ISSUE_BOUND_S, LOAD_FACTOR * _baseline_s(h))
    sources = [f"127.0.0.{2 + i}" for i in range(13)]
    with h.client() as mover, _held(h, 200, sources):
        assert h.running.service.service_status()["service"]["clients"] == 64
        rid = mover.send("move", {"joints_deg": [10, 0, 0, 0, 0, 0]})
        _wait_moving(h)
        reply, took = round_trip(h.running.host, h.running.port, "estop")
        moved = mover.read_reply(timeout_s=10)
    assert reply["ok"], reply
    assert reply["result"]["state"] == "fault" and reply["result"]["stopped_job"] == "move"
    assert took < bound, f"estop took {took * 1e3:.1f} ms with 200 idle connections"
    assert moved["id"] == rid and moved["error"]["code"] == "stopped"
    assert "arm move_joints interrupted" in h.journal.events


def test_stop_and_estop_served_with_every_client_slot_held(make_service) -> None:
    h = make_service(move_seconds=5.0, overflow_grace_s=1.0)
    cfg = h.running.service.config
    sources = [f"127.0.0.{2 + i}" for i in range(cfg.max_clients // cfg.max_clients_per_peer)]
    bound = max(ISSUE_BOUND_S, LOAD_FACTOR * _baseline_s(h))
    with _held(h, cfg.max_clients, sources) as socks:
        refused, _ = round_trip(h.running.host, h.running.port, "status")
        assert (
            refused["error"]["code"] == "busy" and "too many clients" in refused["error"]["message"]
        )
        socks[0].sendall(b'{"id": 2, "cmd": "move", "args": {"joints_deg": [10, 0, 0, 0, 0, 0]}}\n')
        _wait_moving(h)
        stopped, t_stop = round_trip(h.running.host, h.running.port, "stop")
        assert stopped["ok"] and stopped["result"]["stopped_job"] == "move", stopped
        estopped, t_estop = round_trip(h.running.host, h.running.port, "estop")
        assert estopped["ok"] and estopped["result"]["state"] == "fault", estopped
    assert "arm move_joints interrupted" in h.journal.events
    assert max(t_stop, t_estop) < bound, (t_stop, t_estop, bound)


def test_one_address_cannot_take_every_slot(make_service) -> None:
    h = make_service(max_clients_per_peer=2, overflow_grace_s=0.5)
    with _held(h, 2, ["127.0.0.7"]):
        refused, _ = round_trip(h.running.host, h.running.port, "status", "127.0.0.7")
        assert refused["error"]["code"] == "busy"
        assert "127.0.0.7" in refused["error"]["message"]
        other, _ = round_trip(h.running.host, h.running.port, "status", "127.0.0.8")
        assert other["ok"], other


def _closed_within(s: socket.socket, limit_s: float) -> tuple[list[dict], float]:
    """Read until the server closes `s`; (reply lines, seconds it took)."""
    t0 = time.perf_counter()
    s.settimeout(limit_s)
    buf = b""
    while True:
        chunk = s.recv(65536)
        if not chunk:
            break
        buf += chunk
    return [json.loads(x) for x in buf.splitlines() if x], time.perf_counter() - t0


def test_idle_connection_times_out_but_not_while_a_job_runs(make_service) -> None:
    idle_s = 0.5
    h = make_service(move_seconds=1.5, idle_timeout_s=idle_s)
    with socket.create_connection((h.running.host, h.running.port), timeout=10) as idle:
        lines, took = _closed_within(idle, 10 * idle_s)
    assert lines and "idle" in lines[-1]["error"]["message"]
    assert idle_s * 0.9 <= took
    with h.client() as c:
        reply = c.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]}, timeout_s=10)
    assert reply["ok"], reply


def test_line_without_newline_times_out(make_service) -> None:
    line_s = 0.5
    h = make_service(line_timeout_s=line_s)
    with socket.create_connection((h.running.host, h.running.port), timeout=10) as s:
        s.sendall(b"x" * 60_000)
        lines, took = _closed_within(s, 20 * line_s)
    assert lines and "no end of line" in lines[-1]["error"]["message"]
    assert took >= line_s * 0.9
    with h.client() as c:
        assert c.call("status")["ok"]
