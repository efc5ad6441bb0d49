"""What the page says of a request its schema refuses, before sending it: each problem names
its field, and an empty field the request needs says so (not the schema's `null` rule)."""

from __future__ import annotations

from omnisort_hw import sim_requests as sr
from omnisort_hw.pipeline.requests import CalibrateRequest
from omnisort_hw.request_fields import schema_of
from omnisort_hw.ui.schema_form import (
    args_from_form,
    form_fields,
    inapplicable,
    problems,
    typed_number,
)


def test_an_empty_needed_field_is_named_as_missing() -> None:
    schema = schema_of(CalibrateRequest, "calibrate")
    args = {"what": "intrinsics", "folder": "/views", "board": "9x6", "square_mm": None}
    assert problems(schema, args) == ["square_mm: no value given: this request needs one"]
    assert problems(schema, {**args, "square_mm": 20.0}) == []
    low = problems(schema, {"what": "extrinsics", "separation_mm": 0.5})
    assert low == ["separation_mm: 0.5 is less than the minimum of 1.0"], low


def test_a_number_field_reads_what_was_typed() -> None:
    assert typed_number(" 12 ", integer=True) == 12 and isinstance(typed_number("12", True), int)
    assert typed_number("1.5", integer=True) == 1.5  # the schema refuses a fraction by name
    assert typed_number("1084.5") == 1084.5
    assert typed_number("") is None and typed_number("  ") is None
    assert typed_number("abc") == "abc" and typed_number("nan") == "nan"
    schema = schema_of(CalibrateRequest, "calibrate")
    fields = form_fields(schema)
    args = args_from_form(fields, {"what": "extrinsics", "separation_mm": "abc"})
    assert args == {"what": "extrinsics", "separation_mm": "abc"}
    assert problems(schema, args) == ["separation_mm: 'abc' is not of type 'number'"]


def test_a_joint_vector_is_one_field_of_six_numbers() -> None:
    schema = sr.SIM_COMMANDS["joints"].schema()
    (field,) = form_fields(schema)
    assert (field.name, field.kind, field.length) == ("q_deg", "numbers", 6)
    assert field.label == "q_deg -360..360 deg"
    args = args_from_form([field], {"q_deg": ["1", "2", " 3 ", "4", "5", "6.5"]})
    assert args == {"q_deg": [1.0, 2.0, 3.0, 4.0, 5.0, 6.5]} and problems(schema, args) == []
    bad = args_from_form([field], {"q_deg": ["1", "2", "abc", "4", "5", "6"]})
    assert problems(schema, bad) == ["q_deg.2: 'abc' is not of type 'number'"]
    assert args_from_form([field], {"q_deg": [""] * 6}) == {}  # none typed: not given


def test_a_field_the_schema_allows_only_as_null_is_left_out() -> None:
    """A cube's place is not sent with Remove, nor its index with Add, nor a picture's name
    with the board's poses: the schema's if/then rules say which, not the page."""
    cube = sr.SIM_COMMANDS["cube"].schema()
    typed = {"index": 1, "color": "red", "x_mm": 0.0, "y_mm": 900.0, "yaw_deg": 5.0}
    remove = {**typed, "action": "remove"}
    assert inapplicable(cube, remove) == {"color", "x_mm", "y_mm", "yaw_deg"}
    assert inapplicable(cube, {**typed, "action": "add"}) == {"index"}
    assert inapplicable(cube, {**typed, "action": "move"}) == {"color"}
    kept = {k: v for k, v in remove.items() if k not in inapplicable(cube, remove)}
    assert problems(cube, kept) == [] and problems(cube, remove) != []
    render = sr.SIM_COMMANDS["render"].schema()
    assert inapplicable(render, {"folder": "f", "name": "n", "views": True}) == {"name"}
    assert inapplicable(render, {"folder": "f", "name": "n", "views": False}) == set()
