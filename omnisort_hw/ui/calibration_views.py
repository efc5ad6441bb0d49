"""What the two guided flows (commissioning and recovery) show and ask of the camera and laser
plane's calibration alike: its parameters with their 1-sigma in a table, and the walls' measured
separation, which the technician may type (the cell file's `[target]` when left empty)."""

from __future__ import annotations

from typing import Any

from nicegui import ui

from omnisort_hw.pipeline.replies import ExtrinsicsReply
from omnisort_hw.ui.schema_form import typed_number
from omnisort_hw.ui.widgets import number_input, tag

PARAMETER_UNITS = {"_deg": "deg", "_mm": "mm"}
PARAMETER_COLUMNS = ("name", "value", "sigma")
SEPARATION_LABEL = "wall separation (mm): empty for the cell file's"


def parameter_rows(reply: ExtrinsicsReply) -> list[dict[str, str]]:
    """An extrinsic calibration's parameters with their 1-sigma, for a table."""
    rows = []
    for name, value in reply.parameters.items():
        unit = next((u for suffix, u in PARAMETER_UNITS.items() if name.endswith(suffix)), "")
        sigma = reply.std.get(name)
        rows.append(
            {
                "name": name,
                "value": f"{value:.4f} {unit}".strip(),
                "sigma": f"{sigma:.4f} {unit}".strip() if sigma is not None else "not given",
            }
        )
    return rows


def parameter_table(name: str) -> Any:
    """An empty table for `parameter_rows`, named `name` for the tests."""
    columns = [{"name": k, "label": k, "field": k, "align": "left"} for k in PARAMETER_COLUMNS]
    return tag(ui.table(columns=columns, rows=[], row_key="name").props("dense flat"), name)


def separation_input(name: str) -> Any:
    """The walls' measured separation, named `name` for the tests; empty by default."""
    return number_input(SEPARATION_LABEL, name).classes("w-72")


def extrinsics_args(separation: Any) -> dict[str, Any]:
    """The `calibrate` arguments of the camera and laser plane's calibration, with the
    separation typed in the `separation_input` (left out when it is empty)."""
    args: dict[str, Any] = {"what": "extrinsics"}
    typed = typed_number(separation.value)
    if typed is not None:
        args["separation_mm"] = typed  # what is not a number, as typed: the schema names it
    return args
