"""The commands' one declaration (`pipeline.requests`) as the protocol checks it and as its JSON
Schema (draft 2020-12, from `describe`) states it: the two agree on random arguments, judged by
an independent validator (`jsonschema`)."""

from __future__ import annotations

import random
from typing import Any

import pytest
from jsonschema import Draft202012Validator

from omnisort_hw.request_fields import Arg, build
from omnisort_hw.service import protocol as proto
from tests.schema_agreement import schema_accepts, validator
from tests.service.conftest import TOKEN

WITH_ARGS = sorted(name for name, c in proto.COMMANDS.items() if c.args)


def _values(arg: Arg, rng: random.Random) -> tuple[list[Any], list[Any]]:
    """(valid values of `arg`, values of every other shape: just outside its bounds, junk)."""
    lo = arg.lo if arg.lo is not None else -1e6
    hi = arg.hi if arg.hi is not None else 1e6
    number = rng.uniform(lo, hi)
    n = arg.length or 6
    eye = [[float(i == j) for j in range(4)] for i in range(4)]
    valid: dict[str, list[Any]] = {
        "bool": [True, False],
        "int": [int(lo), int(hi), float(int(hi))],
        "number": [number, lo, hi, int(hi)],
        "str": list(arg.choices) or ["9x6", "UR5e"],
        "path": ["/tmp/a.png", "/"],
        "str_list": [["red"], ["red", "blue"]],
        "vector": [[number] * n],
        "matrix4": [eye],
    }
    wrong: dict[str, list[Any]] = {
        "bool": [],
        "int": [int(lo) - 1, int(hi) + 1, 2.5],
        "number": [lo - 1e-3, hi + 1e-3],
        "str": ["z" * (arg.max_chars + 1), *(["nope"] if arg.choices else [])],
        "path": ["rel/a.png", "/a\x00"],
        "str_list": [[""], ["x" * 65], ["a"] * 65, [1]],
        "vector": [[number] * (n - 1), [hi + 1] * n],
        "matrix4": [[[1.0] * 3] * 4, [[hi + 1] * 4] * 4],
    }
    junk: list[Any] = [True, 3, -2.5, "x", "", "a\x00b", [], {}, ["a"], [1.0] * 6]
    return valid[arg.kind] + [None], wrong[arg.kind] + junk


def _random_args(spec: proto.Command, rng: random.Random) -> dict[str, Any]:
    args: dict[str, Any] = {}
    for arg in spec.args:
        if arg.required or rng.random() < 0.3:
            valid, wrong = _values(arg, rng)
            args[arg.name] = rng.choice(valid if rng.random() < 0.85 else wrong)
    if rng.random() < 0.03:
        args["no_such_argument"] = 1
    return args


def test_every_schema_is_a_valid_draft_2020_12_schema() -> None:
    for name, spec in proto.COMMANDS.items():
        schema = spec.schema()
        Draft202012Validator.check_schema(schema)
        assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        assert set(schema["properties"]) == {a.name for a in spec.args}, name


@pytest.mark.parametrize("cmd", WITH_ARGS)
def test_schema_and_protocol_agree_on_random_arguments(cmd: str) -> None:
    """Each draw is taken by both or refused by both; a draw both take builds its request."""
    spec = proto.COMMANDS[cmd]
    rng = random.Random(cmd)
    taken = refused = 0
    for _ in range(1500):
        args = _random_args(spec, rng)
        try:
            checked = proto.validate_args(spec, args)
        except proto.ProtocolError as exc:
            assert exc.code == proto.BAD_ARGUMENT
            assert not schema_accepts(cmd, args), f"protocol refuses {args} ({exc}), schema takes"
            refused += 1
            continue
        errors = [e.message for e in validator(cmd).iter_errors(args)]
        assert not errors, f"protocol takes {args}, schema refuses: {errors}"
        assert isinstance(build(spec.request, checked), spec.request)  # type: ignore[arg-type]
        taken += 1
    assert taken >= 30 and refused >= 30, (taken, refused)  # both sides were exercised


@pytest.mark.parametrize(
    ("cmd", "args", "field"),
    [
        ("calibrate", {"what": "intrinsics", "square_mm": 30}, "folder"),
        (
            "calibrate",
            {"what": "intrinsics", "folder": "/v", "square_mm": 30, "image": "/a"},
            "image",
        ),
        ("calibrate", {"what": "extrinsics", "target": "two-sided", "square_mm": 30}, "square_mm"),
        (
            "calibrate",
            {"what": "extrinsics", "target": "checkerboards", "separation_mm": 9},
            "separation_mm",
        ),
        ("move", {"joints_deg": [0] * 6, "pose": [0] * 6}, "joints_deg|pose|matrix"),
        ("move", {}, "joints_deg|pose|matrix"),
        ("move", {"pose": [0] * 6, "speed_deg_s": 10}, "speed_deg_s"),
        ("move", {"joints_deg": [0] * 6, "speed_mm_s": 10}, "speed_mm_s"),
        ("sort", {"max_objects": 0}, "max_objects"),
        ("map", {"image": "relative.png"}, "image"),
    ],
)
def test_rules_between_arguments_are_refused_by_both(cmd: str, args: dict, field: str) -> None:
    with pytest.raises(proto.ProtocolError) as refused:
        proto.validate_args(proto.COMMANDS[cmd], args)
    assert refused.value.code == proto.BAD_ARGUMENT
    assert refused.value.details["field"] == field
    assert not schema_accepts(cmd, args)


def test_a_request_record_is_built_from_checked_arguments() -> None:
    spec = proto.COMMANDS["sort"]
    request = build(
        spec.request, proto.validate_args(spec, {"colors": ["red"], "max_objects": 2.0})
    )  # type: ignore[arg-type]
    assert (request.colors, request.max_objects, request.register) == (("red",), 2, False)


def test_describe_through_the_service(make_service) -> None:
    """`describe` answers every command with its kind, token rule and schema; off loopback it
    needs the token like any command that is not stop, estop or status."""
    h = make_service(token=TOKEN)
    with h.client(token=TOKEN) as c:
        reply = c.call("describe")
    assert reply["ok"], reply
    commands = reply["result"]["commands"]
    assert set(commands) == set(proto.COMMANDS)
    for name, described in commands.items():
        Draft202012Validator.check_schema(described["args"])
        assert described["kind"] == proto.COMMANDS[name].kind
        assert described["help"], name
    square = commands["calibrate"]["args"]["properties"]["square_mm"]
    assert square["x-unit"] == "mm" and square["anyOf"][0]["minimum"] == 1.0
