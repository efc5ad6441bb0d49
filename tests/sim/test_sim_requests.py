"""The control channel's contract (`omnisort_hw.sim_requests`): its `describe` is valid JSON
Schema, and what the schema refuses the channel's own check refuses too, naming the field (so
the Simulator tab's forms, checked against the schema, and the channel agree)."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from jsonschema import Draft202012Validator

from omnisort_hw import sim_requests as sr
from omnisort_hw.sim_replies import Record, SimBoardHeld
from omnisort_hw.ui.schema_form import problems
from omnisort_hw.wire_records import WireError, from_wire
from sim_backend.scene import NAMED_COLORS


def test_describe_is_json_schema_for_every_command() -> None:
    described = sr.describe_sim().commands
    assert set(described) == set(sr.SIM_COMMANDS)
    for name, spec in described.items():
        Draft202012Validator.check_schema(spec.args)
        assert spec.help, name


# (command, arguments, the field named, or None: accepted by both)
CASES: list[tuple[str, dict[str, Any], str | None]] = [
    ("knock", {"angle_deg": 0.3, "axis": "y"}, None),
    ("knock", {"angle_deg": 1000.0}, "angle_deg"),
    ("knock", {"angle_deg": -10.5}, "angle_deg"),
    ("knock", {"axis": "w"}, "axis"),
    ("board", {"view": sr.HELD_VIEWS - 1}, None),
    ("board", {"view": sr.HELD_VIEWS}, "view"),
    ("camera", {"roll_deg": 190.0}, "roll_deg"),
    ("laser", {"distance_mm": 10.0}, "distance_mm"),
    ("laser", {"on": "yes"}, "on"),
    ("cube", {"action": "add", "color": "blue", "x_mm": 0.0, "y_mm": 900.0}, None),
    ("cube", {"action": "add", "color": "mauve", "x_mm": 0.0, "y_mm": 900.0}, "color"),
    ("cube", {"action": "spin"}, "action"),
    ("joints", {"q_deg": [0.0] * 5}, "q_deg"),
    ("move_to", {"x_mm": 100.0, "y_mm": 0.0}, "z_mm"),
    ("stall", {"what": "arm", "seconds": -1.0}, "seconds"),
    ("truth", {"x": 1}, "x"),
]


@pytest.mark.parametrize(("cmd", "args", "field"), CASES)
def test_the_schema_and_the_channel_agree(
    cmd: str, args: dict[str, Any], field: str | None
) -> None:
    schema = sr.SIM_COMMANDS[cmd].schema()
    found = problems(schema, args)
    if field is None:
        assert found == []
        name, request = sr.validate({"cmd": cmd, **args})
        assert name == cmd and isinstance(request, sr.SIM_COMMANDS[cmd].request)
        return
    assert found and field in " ".join(found), found
    with pytest.raises(ValueError, match=field):
        sr.validate({"cmd": cmd, **args})


def test_a_colour_the_renderer_does_not_paint_is_not_offered() -> None:
    assert set(sr.SIM_COLORS) == set(NAMED_COLORS)


def test_each_record_names_its_command() -> None:
    """The Simulator tab sends records (`SimLink.send`), never a command's name: each command
    with arguments of its own, and truth and describe, is found from its record; the record
    several argument-less commands share names none."""
    for name, spec in sr.SIM_COMMANDS.items():
        if spec.request is sr.NoArgs:
            continue
        assert sr.command_of(spec.request) == name
    assert sr.command_of(sr.TruthRequest()) == "truth"
    assert sr.command_of(sr.DescribeRequest()) == "describe"
    assert sr.command_of(sr.KnockRequest(angle_deg=0.3)) == "knock"
    with pytest.raises(ValueError, match="NoArgs"):
        sr.command_of(sr.NoArgs)


def test_every_command_declares_its_reply_as_a_record() -> None:
    """What the channel answers is declared beside what it is asked: a record of
    `sim_replies` (read by the replies' codec), or the status's `Record` (the controller's own
    keys). `SimLink.control` holds each reply to it."""
    for name, spec in sr.SIM_COMMANDS.items():
        assert spec.reply is Record or dataclasses.is_dataclass(spec.reply), name
    held = from_wire(sr.SIM_COMMANDS["board"].reply, {"view": 3, "views": 12, "shown": True})
    assert held == SimBoardHeld(view=3, views=12, shown=True)
    with pytest.raises(WireError, match=r"SimBoardHeld\.shown: missing"):
        from_wire(sr.SIM_COMMANDS["board"].reply, {"view": 3, "views": 12})
