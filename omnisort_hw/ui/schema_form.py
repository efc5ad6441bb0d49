"""A command's form, read from its JSON Schema (`describe`), and the check of what was typed
against that schema before anything is sent. Pure functions: the page draws the fields and
shows the problems; nothing here knows a command by name."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from jsonschema import Draft202012Validator


@dataclass(frozen=True)
class FormField:
    """One argument as a form offers it."""

    name: str
    kind: str  # bool, int, number, numbers (a fixed count of numbers), choice, list, text
    label: str  # the name, with its unit and bounds
    help: str
    default: Any = None
    choices: tuple[str, ...] = ()
    required: bool = False
    length: int = 0  # a `numbers` field's count


def _branch(prop: Mapping[str, Any]) -> Mapping[str, Any]:
    """The property's schema without its `null` alternative (an omitted argument)."""
    for alt in prop.get("anyOf", ()):
        if alt.get("type") != "null":
            return alt
    return prop


def _bounds(b: Mapping[str, Any], unit: str | None) -> str:
    lo, hi = b.get("minimum"), b.get("maximum")
    span = f" {lo:g}..{hi:g}" if lo is not None and hi is not None else ""
    return f"{span}{f' {unit}' if unit else ''}"


def form_fields(schema: Mapping[str, Any]) -> list[FormField]:
    """The fields of an `args` schema, in its order. A fixed count of numbers (a joint vector)
    is one `numbers` field; open-ended vectors and matrices are left out: no form of this
    interface offers them."""
    required = set(schema.get("required", ()))
    out = []
    for name, prop in (schema.get("properties") or {}).items():
        b = _branch(prop)
        t, xkind = b.get("type"), prop.get("x-kind")
        unit = prop.get("x-unit")
        items = b.get("items") or {}
        length = 0
        if "enum" in b:
            kind, choices = "choice", tuple(str(c) for c in b["enum"])
        elif t == "boolean":
            kind, choices = "bool", ()
        elif t == "integer":
            kind, choices = "int", ()
        elif t == "number":
            kind, choices = "number", ()
        elif t == "array" and xkind == "str_list":
            kind, choices = "list", ()
        elif (
            t == "array"
            and items.get("type") == "number"
            and b.get("maxItems") is not None
            and b.get("minItems") == b.get("maxItems")
        ):
            kind, choices, length = "numbers", (), int(b["maxItems"])
            b = items  # the bounds shown are each number's
        elif t == "string":
            kind, choices = "text", ()
        else:
            continue
        label = name + (_bounds(b, unit) if kind in ("int", "number", "numbers") else "")
        out.append(
            FormField(
                name,
                kind,
                label,
                str(prop.get("description", "")),
                prop.get("default"),
                choices,
                name in required,
                length,
            )
        )
    return out


def typed_number(text: Any, integer: bool = False) -> Any:
    """A number field's text as the number it reads as (an int for an integer field when it is
    whole); None when empty. What is not a finite number stays the text, so the schema refuses
    it by name: a browser's own number field would report it as empty, and an empty field
    means the default (`abc` in max_objects would have sorted every cube)."""
    if not isinstance(text, str):
        return text
    text = text.strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        return text
    if not math.isfinite(value):
        return text
    return int(value) if integer and value.is_integer() else value


def args_from_form(fields: list[FormField], typed: Mapping[str, Any]) -> dict[str, Any]:
    """The `args` object of what was typed: empty fields are left out (the service's default),
    a list is read as `a, b`, and a number as it reads (`typed_number`; the schema judges it)."""
    args: dict[str, Any] = {}
    for f in fields:
        value = typed.get(f.name)
        if f.kind in ("int", "number"):
            value = typed_number(value, f.kind == "int")
        elif f.kind == "numbers" and isinstance(value, list | tuple):
            numbers = [typed_number(v) for v in value]
            value = None if all(v is None for v in numbers) else numbers
        if value is None or (isinstance(value, str) and not value.strip()):
            continue
        if f.kind == "list" and isinstance(value, str):
            value = [item.strip() for item in value.split(",") if item.strip()]
        elif f.kind == "int" and isinstance(value, float) and value.is_integer():
            value = int(value)
        elif f.kind == "bool" and value == f.default:
            continue
        args[f.name] = value
    return args


def problems(schema: Mapping[str, Any], args: Mapping[str, Any]) -> list[str]:
    """What is wrong with `args` by the schema, one message per problem, each naming its
    field; empty when it may be sent."""
    out = []
    for err in sorted(Draft202012Validator(schema).iter_errors(dict(args)), key=str):
        field = ".".join(str(p) for p in err.absolute_path) or "arguments"
        detail = err.message
        if err.instance is None and err.absolute_path:  # an empty field the command needs here
            detail = "no value given: this request needs one"
        elif err.validator == "anyOf":  # the reason of the alternative that is not `null`
            alts = err.schema.get("anyOf", [])
            real = [
                e
                for e in err.context or ()
                if alts[int(e.relative_schema_path[0])].get("type") != "null"
            ]
            if real:
                detail = real[0].message
        out.append(f"{field}: {detail}")
    return out


def inapplicable(schema: Mapping[str, Any], args: Mapping[str, Any]) -> set[str]:
    """The fields the schema allows only as null given the rest of `args` (its `if`/`then`
    rules: a cube's place when it is removed, a picture's name when the board's poses are
    rendered), which a form that holds them leaves out."""
    out: set[str] = set()
    for rule in schema.get("allOf", ()):
        cond, then = rule.get("if"), rule.get("then") or {}
        if cond is None or not Draft202012Validator(cond).is_valid(dict(args)):
            continue
        out |= {k for k, v in (then.get("properties") or {}).items() if v == {"type": "null"}}
    return out
