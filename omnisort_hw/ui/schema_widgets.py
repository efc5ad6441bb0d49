"""A command's form drawn from its JSON Schema (`schema_form.form_fields`): one widget per
argument, named `{prefix}-{name}` for the tests (a fixed count of numbers, such as a joint
vector, is one box per number, `{prefix}-{name}-{i}`), each with its help as its tooltip,
read back as the command's `args`. The sort form and the Simulator tab's forms are drawn by it,
so a form offers what the command declares, with its bounds, units and choices, and nothing
else."""

from __future__ import annotations

from typing import Any

from nicegui import ui
from nicegui.elements.mixins.value_element import ValueElement

from omnisort_hw.ui.schema_form import FormField, args_from_form, inapplicable
from omnisort_hw.ui.widgets import tag


def _text(value: float | None) -> str:
    """A number as a box shows it: rounded to a thousandth, without trailing zeros."""
    return "" if value is None else f"{round(float(value), 3):g}"


class SchemaForm:
    """The widgets of `fields`, drawn in the current container."""

    def __init__(self, fields: list[FormField], prefix: str, width: str = "w-40") -> None:
        self.fields = fields
        self.inputs: dict[str, ValueElement | list[ValueElement]] = {}  # a list: `numbers`
        for f in fields:
            self.inputs[f.name] = self._draw(f, f"{prefix}-{f.name}", width)

    @staticmethod
    def _draw(f: FormField, name: str, width: str) -> ValueElement | list[ValueElement]:
        if f.kind == "numbers":
            default = f.default if isinstance(f.default, list | tuple) else [None] * f.length
            return [
                tag(
                    ui.input(f"{f.name} {i + 1}", value=_text(v)).classes("w-16"), f"{name}-{i}"
                ).tooltip(f"{f.label}: {f.help}")
                for i, v in enumerate(default)
            ]
        if f.kind == "bool":
            field: ValueElement = ui.checkbox(f.label, value=bool(f.default))
        elif f.kind in ("int", "number"):
            field = ui.input(f.label, value=_text(f.default)).classes(width)
        elif f.kind == "choice":
            field = ui.select(list(f.choices), label=f.label, value=f.default).classes("w-32")
            if f.default is None and not f.required:
                field.props("clearable")  # none: left as it is
        else:
            field = ui.input(f.label + (" (a, b)" if f.kind == "list" else ""))
        return tag(field.tooltip(f.help), name)

    def typed(self) -> dict[str, Any]:
        """What each widget holds, as typed."""
        return {
            k: [w.value for w in v] if isinstance(v, list) else v.value
            for k, v in self.inputs.items()
        }

    def args(self, schema: dict[str, Any] | None = None, **fixed: Any) -> dict[str, Any]:
        """The command's `args` from what was typed (`args_from_form`), with `fixed` (what a
        button decides) over them; with the `schema`, less the fields it allows only as null
        given the rest (`schema_form.inapplicable`)."""
        args = {**args_from_form(self.fields, self.typed()), **fixed}
        if schema is not None:
            for name in inapplicable(schema, args) - set(fixed):
                args.pop(name, None)
        return args

    def set(self, name: str, value: object) -> None:
        """One field shown at `value` (a number rounded as `_text`, a `numbers` field's list
        spread over its boxes)."""
        widget = self.inputs[name]
        if isinstance(widget, list):
            values = value if isinstance(value, list | tuple) else ()
            for w, v in zip(widget, values, strict=False):
                w.value = _text(v) if isinstance(v, int | float) else ""
        elif isinstance(value, int | float) and not isinstance(value, bool):
            widget.value = _text(value)
        else:
            widget.value = value
