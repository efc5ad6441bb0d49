"""What the page says of a request its schema refuses, before sending it: each problem names
its field, and an empty field the request needs says so (not the schema's `null` rule)."""

from __future__ import annotations

from omnisort_hw.pipeline.requests import CalibrateRequest
from omnisort_hw.request_fields import schema_of
from omnisort_hw.ui.schema_form import args_from_form, form_fields, problems, typed_number


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
