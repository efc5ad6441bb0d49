"""Request parsing and validation, field by field, without a server."""

from __future__ import annotations

import json

import pytest

from omnisort_hw.config.cell import CellConfig
from omnisort_hw.config.service import ServiceConfig, is_loopback
from omnisort_hw.errors import ConfigError
from omnisort_hw.service import protocol as proto


def parse(obj: object) -> proto.Request:
    return proto.parse_request(json.dumps(obj).encode())


def code_of(line: bytes) -> str:
    with pytest.raises(proto.ProtocolError) as info:
        proto.parse_request(line)
    assert info.value.code in proto.ERROR_CODES
    assert info.value.message
    return info.value.code


def test_minimal_status() -> None:
    req = parse({"id": 1, "cmd": "status"})
    assert (req.id, req.cmd, req.args, req.token) == (1, "status", {}, None)
    assert parse({"cmd": "status", "args": None}).id is None
    assert parse({"id": "abc", "cmd": "status"}).id == "abc"


def test_defaults_are_filled_in() -> None:
    req = parse({"cmd": "capture"})
    assert req.args == {"encoding": "path", "format": "png", "laser": None}
    assert parse({"cmd": "laser", "args": {"on": True}}).args == {"on": True}


@pytest.mark.parametrize(
    ("line", "code"),
    [
        (b"", "bad_json"),
        (b"   ", "bad_json"),
        (b"{", "bad_json"),
        (b"\xff\xfe", "bad_json"),
        (b'{"cmd": "status", "id": NaN}', "bad_json"),
        (b"[" * 5000 + b"]" * 5000, "bad_json"),
        (b'{"a":' * 40 + b"1" + b"}" * 40, "bad_json"),
        (b"1" * 5000, "bad_json"),
        (b"[1, 2]", "bad_request"),
        (b'"status"', "bad_request"),
        (b"null", "bad_request"),
        (b'{"id": 1}', "bad_request"),
        (b'{"cmd": 5}', "bad_request"),
        (b'{"cmd": "status", "extra": 1}', "bad_request"),
        (b'{"cmd": "status", "id": true}', "bad_request"),
        (b'{"cmd": "status", "id": 1e300}', "bad_request"),
        (b'{"cmd": "status", "id": [1]}', "bad_request"),
        (b'{"cmd": "status", "args": [1]}', "bad_request"),
        (b'{"cmd": "status", "token": 5}', "bad_request"),
        (b'{"cmd": "Status"}', "unknown_command"),
        (b'{"cmd": "rm -rf /"}', "unknown_command"),
        (b'{"cmd": "status", "args": {"x": 1}}', "bad_argument"),
    ],
)
def test_malformed_lines(line: bytes, code: str) -> None:
    assert code_of(line) == code


@pytest.mark.parametrize(
    ("cmd", "args", "field"),
    [
        ("laser", {"on": 1}, "on"),
        ("laser", {"on": "true"}, "on"),
        ("capture", {"encoding": "hex"}, "encoding"),
        ("capture", {"format": ""}, "format"),
        ("calibrate", {}, "what"),
        ("calibrate", {"what": "intrinsics"}, "folder"),
        ("calibrate", {"what": "intrinsics", "folder": "/x"}, "square_mm"),
        ("calibrate", {"what": "extrinsics", "target": "two-sided", "square_mm": 20}, "square_mm"),
        ("calibrate", {"what": "extrinsics", "degree": 3}, "degree"),
        ("calibrate", {"what": "extrinsics", "method": "best"}, "method"),
        (
            "calibrate",
            {"what": "extrinsics", "target": "checkerboards", "separation_mm": 9},
            "separation_mm",
        ),
        (
            "calibrate",
            {"what": "intrinsics", "folder": "/x", "square_mm": 2, "image": "a"},
            "image",
        ),
        (
            "calibrate",
            {"what": "intrinsics", "folder": "/x", "square_mm": 20, "degree": 1},
            "degree",
        ),
        ("calibrate", {"what": "extrinsics", "folder": "/x"}, "folder"),
        ("calibrate", {"what": "intrinsics", "folder": "a\x00b", "square_mm": 1}, "folder"),
        ("calibrate", {"what": "intrinsics", "folder": "x" * 5000, "square_mm": 1}, "folder"),
        ("move", {}, "joints_deg|pose|matrix"),
        ("move", {"joints_deg": [0] * 5}, "joints_deg"),
        ("move", {"joints_deg": [0, 0, 0, 0, 0, 400]}, "joints_deg"),
        ("move", {"joints_deg": [0, 0, 0, 0, 0, "1"]}, "joints_deg"),
        ("move", {"joints_deg": [0, 0, 0, 0, 0, True]}, "joints_deg"),
        ("move", {"joints_deg": [0] * 6, "pose": [0] * 6}, "joints_deg|pose|matrix"),
        ("move", {"matrix": [[1, 0, 0, 0]] * 3}, "matrix"),
        ("move", {"joints_deg": [0] * 6, "speed_mm_s": 10}, "speed_mm_s"),
        ("move", {"pose": [0] * 6, "speed_deg_s": 10}, "speed_deg_s"),
        ("move", {"joints_deg": [0] * 6, "speed_deg_s": -1}, "speed_deg_s"),
        ("sort", {"max_objects": 0}, "max_objects"),
        ("sort", {"max_objects": 2.5}, "max_objects"),
        ("sort", {"colors": "red"}, "colors"),
        ("sort", {"colors": []}, "colors"),
        ("locate", {"colors": [1]}, "colors"),
        ("stop", {"now": True}, "now"),
    ],
)
def test_bad_arguments_name_the_field(cmd: str, args: dict, field: str) -> None:
    with pytest.raises(proto.ProtocolError) as info:
        parse({"id": 3, "cmd": cmd, "args": args})
    assert info.value.code == "bad_argument"
    assert info.value.details["field"] == field
    assert info.value.details["id"] == 3
    reply = proto.reply_for(info.value)
    assert reply["id"] == 3 and reply["ok"] is False
    assert reply["error"]["code"] == "bad_argument"


def test_valid_move_targets() -> None:
    assert parse({"cmd": "move", "args": {"joints_deg": [0, -90, 90, 0, 90, 0]}}).args[
        "joints_deg"
    ] == [0.0, -90.0, 90.0, 0.0, 90.0, 0.0]
    eye = [[1, 0, 0, 400], [0, 1, 0, 0], [0, 0, 1, 300], [0, 0, 0, 1]]
    req = parse({"cmd": "move", "args": {"matrix": eye, "speed_mm_s": 50}})
    assert req.args["matrix"][0][3] == 400
    assert parse({"cmd": "move", "args": {"pose": [400, 0, 300, 180, 0, 0]}}).args["pose"]


def test_encode_is_one_line_and_json_safe() -> None:
    import numpy as np

    line = proto.encode({"id": 1, "ok": True, "result": {"a": np.arange(3), "b": float("nan")}})
    assert line.endswith(b"\n") and line.count(b"\n") == 1
    assert json.loads(line)["result"] == {"a": [0, 1, 2], "b": None}
    line = proto.encode(proto.error_reply(None, "bad_json", "multi\nline"))
    assert line.count(b"\n") == 1


def test_every_command_declares_token_policy() -> None:
    """Without the token: what reads (the status, a live picture, the cell in 3D) and what
    stops."""
    free = {name for name, c in proto.COMMANDS.items() if not c.needs_token}
    assert free == {"status", "view", "geometry", "stop", "estop"} == set(proto.OPEN_COMMANDS)


def test_loopback_and_token_config() -> None:
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.5")
    assert not ServiceConfig().token_required
    assert ServiceConfig(token="x" * 16).token_required
    assert ServiceConfig(host="0.0.0.0", token="x" * 16).token_required
    with pytest.raises(ConfigError, match="not loopback"):
        ServiceConfig.from_mapping({"host": "0.0.0.0"})
    with pytest.raises(ConfigError, match="at least 16"):
        ServiceConfig.from_mapping({"token": "short"})
    cfg = ServiceConfig.from_mapping({"host": "0.0.0.0", "token": "s" * 20, "port": 1234})
    assert cfg.token_required and cfg.port == 1234
    with pytest.raises(ConfigError, match="unknown"):
        CellConfig.from_mapping({"service": {"hots": "x"}})


def test_token_file(tmp_path) -> None:
    (tmp_path / "token").write_text("t" * 32 + "\n")
    cfg = ServiceConfig.from_mapping({"token_file": "token"}, base_dir=tmp_path)
    assert cfg.token == "t" * 32
    with pytest.raises(ConfigError, match="token_file"):
        ServiceConfig.from_mapping({"token_file": "missing"}, base_dir=tmp_path)
