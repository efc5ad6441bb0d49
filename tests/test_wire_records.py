"""The replies' codec: a record written by `to_wire` reads back equal through `from_wire`; a
key left out while None (`absent()`), a null where the type allows it; and a reply that does
not fit its record is refused with the record's and the field's path."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import pytest

from omnisort_hw.pipeline.replies import ArmReply, BinReply, GeometryReply, LaserPlaneReply
from omnisort_hw.wire_records import WireError, absent, from_wire, to_wire


@dataclass(frozen=True)
class Inner:
    level: Literal["pass", "warn", "fail"]
    count: int


@dataclass(frozen=True)
class Outer:
    name: str
    ratio: float
    inner: Inner
    items: list[Inner]
    pair: tuple[float, float]
    by_name: dict[str, float]
    raw: dict[str, Any]
    maybe: float | None
    note: str | None = absent()
    tags: list[str] = field(default_factory=list)


def _outer(**changes: Any) -> Outer:
    base = Outer(
        name="a",
        ratio=0.5,
        inner=Inner("warn", 2),
        items=[Inner("pass", 0), Inner("fail", 3)],
        pair=(1.0, 2.0),
        by_name={"x": 1.5},
        raw={"anything": [1, "b", None]},
        maybe=None,
    )
    return Outer(**{**base.__dict__, **changes})


def test_a_record_reads_back_equal_through_json() -> None:
    for record in (_outer(), _outer(note="seen", tags=["t"], maybe=2.0)):
        wire = json.loads(json.dumps(to_wire(record)))
        assert from_wire(Outer, wire) == record


def test_an_absent_field_leaves_its_key_out_and_a_null_stays() -> None:
    wire = to_wire(_outer())
    assert "note" not in wire and wire["maybe"] is None
    assert to_wire(_outer(note="x"))["note"] == "x"


def test_the_cell_geometry_reads_back_equal() -> None:
    geometry = GeometryReply(
        cube_size_mm=50.0,
        camera_R_SC=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        laser_plane=LaserPlaneReply([0.0, 0.0, 1.0], 200.0, [[0.0, 0.0, -200.0]] * 4),
        bins=[BinReply("red", [[1.0, 2.0, 3.0]] * 4, [[1.0, 2.0, 0.0]] * 4)],
        arm=ArmReply("ur5e", [0.0] * 6, [[0.0, 0.0, 0.0]]),
    )
    assert from_wire(GeometryReply, json.loads(json.dumps(to_wire(geometry)))) == geometry
    assert from_wire(GeometryReply, {"cube_size_mm": 50}) == GeometryReply(50.0)


@pytest.mark.parametrize(
    ("change", "path"),
    [
        ({"inner": {"level": "bad", "count": 1}}, "Outer.inner.level"),
        ({"items": [{"level": "pass", "count": 0}, {"level": "pass"}]}, "Outer.items[1].count"),
        ({"ratio": "0.5"}, "Outer.ratio"),
        ({"ratio": True}, "Outer.ratio"),  # a boolean is no number here, though Python says so
        ({"inner": {"level": "pass", "count": 1.5}}, "Outer.inner.count"),
        ({"pair": [1.0]}, "Outer.pair"),
        ({"by_name": {"x": "1"}}, "Outer.by_name.x"),
        ({"maybe": "none"}, "Outer.maybe"),
        ({"items": {"level": "pass"}}, "Outer.items"),
    ],
)
def test_a_reply_that_does_not_fit_is_refused_by_its_path(
    change: dict[str, Any], path: str
) -> None:
    wire = {**to_wire(_outer()), **change}
    with pytest.raises(WireError) as refused:
        from_wire(Outer, wire)
    assert refused.value.path == path, refused.value


def test_a_missing_key_is_named() -> None:
    wire = to_wire(_outer())
    del wire["inner"]
    with pytest.raises(WireError, match=r"Outer\.inner: missing"):
        from_wire(Outer, wire)
    not_an_object = r"GeometryReply: must be an object, got \[1, 2\] \(list\)"
    with pytest.raises(WireError, match=not_an_object):
        from_wire(GeometryReply, [1, 2])


def test_a_null_float_is_nan_and_a_null_optional_is_none() -> None:
    """Strict JSON has no NaN (the protocol sends it as null): a null where a float is
    declared reads back as NaN; where None is allowed it stays None."""
    read = from_wire(Outer, {**to_wire(_outer()), "ratio": None, "maybe": None})
    assert math.isnan(read.ratio) and read.maybe is None


def test_the_protocol_writes_a_record_as_its_json_with_nan_as_null() -> None:
    """A record that reaches the protocol's encoder unwritten is sent as its JSON (never its
    repr), a NaN as null, as strict JSON needs."""
    from omnisort_hw.service.protocol import encode

    sent = json.loads(encode({"result": _outer(ratio=float("nan"))}))
    assert sent["result"] == {**to_wire(_outer()), "ratio": None}
    assert from_wire(Outer, sent["result"]).maybe is None
