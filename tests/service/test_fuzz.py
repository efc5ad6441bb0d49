"""10,000 malformed or hostile requests against the service in a subprocess.

Random bytes, invalid UTF-8, huge lines, JSON of the wrong shape, wrong argument types,
unknown commands and fields, missing or wrong tokens. Each line gets exactly one reply, a typed
error, and the service stays up and keeps answering `status`. Seeded; bounded in time.
"""

from __future__ import annotations

import json
import random
import signal
import socket
import subprocess
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest

from omnisort_hw.service.client import Client
from omnisort_hw.service.protocol import COMMANDS, ERROR_CODES
from tests.service.procs import start_service

TOKEN = "fuzz-token-0123456789abcdef"
N_REQUESTS = 10_000
MAX_LINE = 65536


def _rand_bytes(rng: random.Random, lo: int, hi: int) -> bytes:
    return bytes(rng.getrandbits(8) for _ in range(rng.randint(lo, hi))).replace(b"\n", b"")


def _j(obj: object) -> bytes:
    return json.dumps(obj).encode()


def generators(rng: random.Random) -> list[tuple[str, Callable[[], bytes], set[str]]]:
    """(name, make line, acceptable codes); lines never contain a newline."""
    token_cmds = [c for c, s in COMMANDS.items() if s.needs_token]
    junk_values = [None, True, 1, -1.5, "x", [], {}, [1, "a"], {"a": 1}, "9" * 50, 1e308]

    def wrong_type() -> bytes:
        cmd = rng.choice(["capture", "laser", "calibrate", "move", "sort", "locate", "map"])
        spec = COMMANDS[cmd]
        arg = rng.choice(spec.args)
        valid = {
            "str": lambda v: isinstance(v, str),
            "path": lambda v: False,  # no junk value is an absolute path
            "bool": lambda v: isinstance(v, bool),
            "int": lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= 1,
            "number": lambda v: False,
            "str_list": lambda v: False,
            "vector": lambda v: False,
            "matrix4": lambda v: False,
        }[arg.kind]
        bad = rng.choice([v for v in junk_values if v is not None and not valid(v)])
        return _j(
            {"id": rng.randint(0, 10**6), "cmd": cmd, "args": {arg.name: bad}, "token": TOKEN}
        )

    def missing_token() -> bytes:
        cmd = rng.choice(token_cmds)
        req: dict = {"id": rng.randint(0, 10**6), "cmd": cmd}
        if rng.random() < 0.5:
            req["token"] = rng.choice(["", "wrong", TOKEN[:-1], TOKEN + "x", "🔑" * 10])
        return _j(req)

    def deep() -> bytes:
        n = rng.randint(17, 20000)
        return b'{"cmd": "status", "args": ' + b"[" * n + b"]" * n + b"}"

    return [
        ("random_bytes", lambda: _rand_bytes(rng, 1, 300), {"bad_json", "bad_request"}),
        ("bad_utf8", lambda: b'{"cmd": "st\xc3\x28tus"}', {"bad_json"}),
        ("huge_line", lambda: b"x" * rng.randint(MAX_LINE + 1, 4 * MAX_LINE), {"bad_request"}),
        (
            "not_object",
            lambda: _j(rng.choice([1, "status", [1, 2], None, 2.5, True])),
            {"bad_request"},
        ),
        ("deep", deep, {"bad_json"}),
        ("nan", lambda: b'{"cmd": "move", "args": {"joints_deg": [NaN,0,0,0,0,0]}}', {"bad_json"}),
        ("unknown_cmd", lambda: _j({"cmd": _rand_bytes(rng, 1, 20).hex()}), {"unknown_command"}),
        ("cmd_type", lambda: _j({"cmd": rng.choice([True, 1, 2.5, [], {}])}), {"bad_request"}),
        ("no_cmd", lambda: _j({"id": 1, "args": {}}), {"bad_request"}),
        ("unknown_field", lambda: _j({"cmd": "status", "evil": 1}), {"bad_request"}),
        (
            "bad_id",
            lambda: _j({"cmd": "status", "id": rng.choice([True, [1], {}, 2**60, "i" * 200])}),
            {"bad_request"},
        ),
        (
            "args_type",
            lambda: _j({"cmd": "sort", "args": rng.choice([[], "a", 3]), "token": TOKEN}),
            {"bad_request"},
        ),
        ("unknown_arg", lambda: _j({"cmd": "status", "args": {"verbose": True}}), {"bad_argument"}),
        ("wrong_type", wrong_type, {"bad_argument"}),
        ("missing_token", missing_token, {"unauthorized"}),
        ("empty", lambda: rng.choice([b"", b" ", b"\t", b"\r"]), {"bad_json"}),
        (
            "truncated",
            lambda: _j({"cmd": "status", "id": 5})[: rng.randint(1, 20)],
            {"bad_json", "bad_request"},
        ),
    ]


@pytest.mark.timeout(120)
def test_ten_thousand_hostile_requests(tmp_path: Path) -> None:
    proc, host, port = start_service(tmp_path, "--token", TOKEN)
    rng = random.Random(20261122)
    gens = generators(rng)
    weights = [10 if name == "huge_line" else 60 for name, _, _ in gens]
    seen: Counter[str] = Counter()
    codes: Counter[str] = Counter()
    t0 = time.monotonic()
    try:
        client = Client(host, port, timeout_s=10)
        for i in range(N_REQUESTS):
            name, make, accept = rng.choices(gens, weights)[0]
            line = make()
            client.send_raw(line + b"\n")
            reply = client.read_reply()
            seen[name] += 1
            assert reply["ok"] is False, (name, line[:200], reply)
            code = reply["error"]["code"]
            codes[code] += 1
            assert code in ERROR_CODES and code in accept, (name, line[:200], reply)
            assert isinstance(reply["error"]["message"], str) and reply["error"]["message"]
            if i % 500 == 0:
                assert client.call("status")["ok"]
            if i % 2000 == 1999:
                client.close()
                client = Client(host, port, timeout_s=10)
        assert client.call("status")["result"]["state"] == "idle"
        # Hostile disconnects: half a line, a huge unterminated line, a reset connection.
        for payload in (b'{"cmd": "sta', b"y" * (3 * MAX_LINE), _rand_bytes(rng, 10, 100)):
            with socket.create_connection((host, port), timeout=5) as s:
                s.sendall(payload)
        with Client(host, port, timeout_s=10) as after:
            st = after.call("status")["result"]
            assert st["state"] == "idle"
            assert st["service"]["errors"] >= N_REQUESTS
        assert proc.poll() is None, "service died"
    finally:
        elapsed = time.monotonic() - t0
        proc.send_signal(signal.SIGTERM)
        try:
            rc = proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    print(f"\n{N_REQUESTS} hostile requests in {elapsed:.1f} s")
    print(f"kinds {dict(seen)}\ncodes {dict(codes)}")
    assert rc == 0
    assert sum(seen.values()) == N_REQUESTS
    assert len(seen) == len(gens)
