"""One declaration of a request's arguments: `param()` field metadata, and what is made of it.

A request dataclass (`pipeline.requests`) declares each argument once, with its type, unit,
bounds, choices, default and help, and the rules between arguments (`only_when`,
`required_when`, `EXACTLY_ONE`). From that declaration come:

- `args_of(cls)`: the `Arg` records the protocol checks a request's arguments against;
- `check_rules(cls, args)`: the rules between arguments, as `ArgumentError` naming the field;
- `check_args(cls, command, raw)`: every argument checked, defaults filled, then the rules
  (what the service's protocol and the virtual cell's control channel check with);
- `schema_of(cls)`: the JSON Schema (draft 2020-12) of the arguments object, which any client
  (the browser interface, `omnisort ctl describe`) builds its forms and checks from;
- `build(cls, args)`: the request itself from checked arguments.

A value of None (or an absent key) always means "not given": the field's default.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import types
import typing
from collections.abc import Callable, Collection, Mapping
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any, ClassVar, Literal, Protocol, TypeAlias, TypeGuard

from omnisort_hw.errors import InputError

SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
MAX_STR_CHARS = 4096
MAX_LIST_ITEMS = 64
MAX_ITEM_CHARS = 64

ArgKind = Literal["bool", "int", "number", "str", "path", "vector", "matrix4", "str_list"]


class _Given:
    """The condition "this other argument is given (not None)"."""

    def __repr__(self) -> str:
        return "GIVEN"


GIVEN = _Given()
Condition: TypeAlias = tuple[str, "tuple[object, ...] | _Given"]
"""(other argument, the values it must have, None meaning "not given"; or GIVEN)."""


class ArgumentError(InputError):
    """An argument of a request is out of its declaration (the message names the field;
    `reason`, what is wrong with its value alone, for a door that names the field its own way)."""

    def __init__(self, field: str, message: str, reason: str | None = None) -> None:
        super().__init__(message)
        self.field, self.reason = field, reason or message


@dataclass(frozen=True)
class Param:
    """The declaration of one argument beyond its Python type (kept as field metadata)."""

    help: str
    unit: str | None = None
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    kind: ArgKind | None = None  # when the annotation does not say it: "path", "matrix4"
    length: int | None = None  # a vector's number of elements
    max_chars: int = MAX_STR_CHARS
    only_when: tuple[Condition, ...] = ()  # refused unless every condition holds
    required_when: tuple[Condition, ...] = ()  # needed when every condition holds
    why: str | None = None  # the refusal's reason when only_when fails (default: the condition)
    flag: str | None = None  # the CLI's spelling when not --field-name ("image": positional)


def param(default: Any = MISSING, **declaration: Any) -> Any:
    """A dataclass field declared as a request argument: `param(None, help=..., unit="mm")`."""
    return dataclasses.field(default=default, metadata={"param": Param(**declaration)})


@dataclass(frozen=True)
class Arg:
    """One argument as every door sees it: its JSON kind, checks, default and help."""

    name: str
    kind: ArgKind
    required: bool = False
    default: Any = None
    choices: tuple[str, ...] = ()
    length: int | None = None
    lo: float | None = None
    hi: float | None = None
    max_chars: int = MAX_STR_CHARS
    help: str = ""
    unit: str | None = None
    only_when: tuple[Condition, ...] = ()
    required_when: tuple[Condition, ...] = ()
    why: str | None = None
    flag: str | None = None

    @property
    def cli_flag(self) -> str:
        """The CLI's spelling: `--square-mm`, or the declared one (a positional's name)."""
        return self.flag or "--" + self.name.replace("_", "-")


class RequestClass(Protocol):
    """A request dataclass (its fields declared with `param`)."""

    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]


def _kind(hint: Any, name: str) -> tuple[ArgKind, bool]:
    """(argument kind, optional) of a field's annotation."""
    optional = False
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        optional = len(members) < len(typing.get_args(hint))
        if len(members) != 1:
            raise TypeError(f"{name}: one type (or None) per argument, got {hint}")
        hint = members[0]
    simple: dict[Any, ArgKind] = {bool: "bool", int: "int", float: "number", str: "str"}
    if hint in simple:
        return simple[hint], optional
    if hint is Path:
        return "path", optional
    if typing.get_origin(hint) is tuple:
        item = typing.get_args(hint)[0]
        if item is str:
            return "str_list", optional
        if item is float:
            return "vector", optional
        if typing.get_origin(item) is tuple:
            return "matrix4", optional
    raise TypeError(f"{name}: no argument kind for {hint}")


def args_of(cls: type[RequestClass]) -> tuple[Arg, ...]:
    """The `Arg` of each field of `cls` declared with `param` (in declaration order); read
    once per record, as every request checks and builds with them."""
    return _declared_args(cls)


@functools.cache
def _declared_args(cls: type) -> tuple[Arg, ...]:
    hints = typing.get_type_hints(cls)
    out: list[Arg] = []
    for f in dataclasses.fields(cls):
        p = f.metadata.get("param")
        if not isinstance(p, Param):
            continue
        kind, _ = _kind(hints[f.name], f"{cls.__name__}.{f.name}")
        kind = p.kind or kind
        default = None if f.default is MISSING else f.default
        out.append(
            Arg(
                f.name,
                kind,
                required=f.default is MISSING and f.default_factory is MISSING,
                default=list(default) if isinstance(default, tuple) else default,
                choices=p.choices,
                length=p.length,
                lo=p.lo,
                hi=p.hi,
                max_chars=p.max_chars,
                help=p.help,
                unit=p.unit,
                only_when=p.only_when,
                required_when=p.required_when,
                why=p.why,
                flag=p.flag,
            )
        )
    return tuple(out)


def type_name(value: object) -> str:
    """A value's JSON type name, for messages."""
    return {
        bool: "boolean",
        int: "integer",
        float: "number",
        str: "string",
        list: "array",
        tuple: "array",
        dict: "object",
    }.get(type(value), "null" if value is None else type(value).__name__)


def _bad(arg: Arg, command: str, what: str, label: str | None) -> ArgumentError:
    return ArgumentError(arg.name, f"{command}: argument {label or repr(arg.name)} {what}", what)


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _range_text(arg: Arg) -> str:
    """`within 1..1000 mm`, `>= 1`: the bounds a number must keep, in words."""
    unit = f" {arg.unit}" if arg.unit else ""
    if arg.lo is not None and arg.hi is not None:
        return f"within {arg.lo:g}..{arg.hi:g}{unit}"
    if arg.lo is not None:
        return f">= {arg.lo:g}{unit}"
    return f"<= {arg.hi:g}{unit}" if arg.hi is not None else ""


def _number(arg: Arg, command: str, value: object, label: str | None, where: str = "") -> float:
    if not _is_number(value):
        raise _bad(arg, command, f"{where}must be a number, got {type_name(value)}", label)
    try:
        number = float(value)
    except OverflowError:
        number = math.inf
    outside = (arg.lo is not None and not number >= arg.lo) or (
        arg.hi is not None and not number <= arg.hi
    )
    if not math.isfinite(number) or outside:
        what = " ".join(w for w in ("a finite number", _range_text(arg)) if w)
        raise _bad(arg, command, f"{where}must be {what}, got {number:g}", label)
    return number


def check_value(
    arg: Arg, command: str, value: object, *, label: str | None = None, cell_paths: bool = True
) -> Any:
    """The checked value of one given (not None) argument, or ArgumentError naming it (as
    `label`, default its name). `cell_paths`: a path must be absolute (a path on the cell PC,
    sent over the network); the CLI reads its own relative paths."""
    if arg.kind == "bool":
        if not isinstance(value, bool):
            raise _bad(arg, command, f"must be true or false, got {type_name(value)}", label)
        return value
    if arg.kind == "int":
        # JSON has one number type: 3.0 is the integer 3 (as JSON Schema's "integer" says).
        integral = isinstance(value, float) and math.isfinite(value) and value.is_integer()
        if not integral and (not isinstance(value, int) or isinstance(value, bool)):
            raise _bad(arg, command, f"must be an integer, got {type_name(value)}", label)
        return int(_number(arg, command, value, label))
    if arg.kind == "number":
        return _number(arg, command, value, label)
    if arg.kind in ("str", "path"):
        if not isinstance(value, str):
            raise _bad(arg, command, f"must be a string, got {type_name(value)}", label)
        if not value or len(value) > arg.max_chars:
            raise _bad(arg, command, f"must be 1..{arg.max_chars} characters", label)
        if "\x00" in value:
            raise _bad(arg, command, "must not contain NUL characters", label)
        if arg.choices and value not in arg.choices:
            choices = ", ".join(arg.choices)
            raise _bad(arg, command, f"must be one of {choices}, got {value[:40]!r}", label)
        if arg.kind == "path" and cell_paths and not os.path.isabs(value):
            raise _bad(
                arg,
                command,
                f"must be an absolute path on the cell PC, got {value[:200]!r}: the service "
                f"does not guess a base folder (its working directory is {os.getcwd()})",
                label,
            )
        return value
    if arg.kind == "str_list":
        if not isinstance(value, list | tuple) or not 1 <= len(value) <= MAX_LIST_ITEMS:
            raise _bad(arg, command, f"must be an array of 1..{MAX_LIST_ITEMS} strings", label)
        for item in value:
            if not isinstance(item, str) or not 1 <= len(item) <= MAX_ITEM_CHARS:
                what = f"must hold strings of 1..{MAX_ITEM_CHARS} characters"
                raise _bad(arg, command, what, label)
        return list(value)
    if arg.kind == "vector":
        if not isinstance(value, list | tuple) or len(value) != arg.length:
            raise _bad(arg, command, f"must be an array of {arg.length} numbers", label)
        return [_number(arg, command, v, label, f"element {i} ") for i, v in enumerate(value)]
    rows_text = "must be a 4x4 array of numbers (rows)"
    if not isinstance(value, list | tuple) or len(value) != 4:
        raise _bad(arg, command, rows_text, label)
    rows = []
    for r, row in enumerate(value):
        if not isinstance(row, list | tuple) or len(row) != 4:
            raise _bad(arg, command, rows_text, label)
        rows.append([_number(arg, command, v, label, f"[{r}][{c}] ") for c, v in enumerate(row)])
    return rows


def _holds(condition: Condition, args: Mapping[str, object]) -> bool:
    other, values = condition
    value = args.get(other)
    if isinstance(values, _Given):
        return value is not None
    return value in values


def condition_text(condition: Condition) -> str:
    """`what=extrinsics`, `with joints_deg`, `without joints_deg`: a condition in words."""
    other, values = condition
    if isinstance(values, _Given):
        return f"with {other}"
    given = [str(v) for v in values if v is not None]
    if not given:
        return f"without {other}"
    return f"{other}={' or '.join(given)}"


def check_rules(
    cls: type[RequestClass],
    command: str,
    args: Mapping[str, object],
    labels: Mapping[str, str] | None = None,
    supplied: Collection[str] = (),
) -> None:
    """The rules between the arguments of `args` (each checked alone already): a field given
    outside its `only_when`, missing under its `required_when`, or not exactly one of
    `EXACTLY_ONE`, as ArgumentError naming the field (in messages as `labels[name]`, the CLI's
    flag, when given). `supplied` names arguments a door gives in its own way (the CLI's list
    of images for the intrinsics' `folder`): never missing."""
    declared = args_of(cls)
    shown = {a.name: (labels or {}).get(a.name, a.name) for a in declared}
    for arg in declared:
        needed = arg.required_when and all(_holds(c, args) for c in arg.required_when)
        if needed and args.get(arg.name) is None and arg.name not in supplied:
            when = " and ".join(condition_text(c) for c in arg.required_when)
            text = f"{command} {when} needs {shown[arg.name]} ({arg.help})"
            raise ArgumentError(arg.name, text)
    for arg in declared:
        if args.get(arg.name) is None:
            continue
        failed = next((c for c in arg.only_when if not _holds(c, args)), None)
        if failed is not None:
            reason = arg.why or f"is for {condition_text(failed)}"
            raise ArgumentError(arg.name, f"{command}: {shown[arg.name]} {reason}")
    group: tuple[str, ...] = getattr(cls, "EXACTLY_ONE", ())
    if group and sum(args.get(k) is not None for k in group) != 1:
        by_name = {a.name: a for a in declared}
        options = "; ".join(f"{k} ({by_name[k].help})" for k in group)
        raise ArgumentError("|".join(group), f"{command} needs exactly one of: {options}")


def check_args(
    cls: type[RequestClass] | None, command: str, raw: Mapping[str, object]
) -> dict[str, Any]:
    """Every argument of `raw` checked against `cls`'s declaration (None: a command without
    arguments), the defaults filled in, then the rules between them; ArgumentError naming the
    field, an unknown or a missing one included. What every channel that takes requests (the
    service's protocol, the virtual cell's control channel) checks with."""
    declared = args_of(cls) if cls is not None else ()
    unknown = sorted(set(raw) - {a.name for a in declared})
    if unknown:
        allowed = ", ".join(a.name for a in declared) or "none"
        shown = ", ".join(repr(k[:32]) for k in unknown[:5])
        text = f"{command}: unknown argument(s) {shown}; allowed: {allowed}"
        raise ArgumentError(unknown[0][:32], text)
    args: dict[str, Any] = {}
    for arg in declared:
        value = raw.get(arg.name)
        if value is None:
            if arg.required:
                raise ArgumentError(arg.name, f"{command}: argument {arg.name!r} is required")
            args[arg.name] = arg.default
            continue
        args[arg.name] = check_value(arg, command, value)
    if cls is not None:
        check_rules(cls, command, args)
    return args


def check_given(
    cls: type[RequestClass],
    values: Mapping[str, object],
    where: str,
    label: Callable[[Arg], str],
    error: type[Exception],
) -> dict[str, Any]:
    """The values of `cls`'s arguments that are given (not None), each checked as a setting
    (a cell file's key or a CLI flag: a relative path is taken as it is); a problem is an
    `error` whose message starts with the key as `label` names it (`[registration].square_mm`,
    or `--square`). `where`: what the values came from."""
    checked: dict[str, Any] = {}
    for arg in args_of(cls):
        value = values.get(arg.name)
        if value is None:
            continue
        try:
            checked[arg.name] = check_value(arg, where, value, label=label(arg), cell_paths=False)
        except ArgumentError as exc:
            raise error(f"{label(arg)}: {exc.reason}") from None
    return checked


def build(cls: type[Any], args: Mapping[str, Any]) -> Any:
    """The request `cls` from checked arguments (JSON arrays become tuples; None: default)."""
    values: dict[str, Any] = {}
    for arg in args_of(cls):
        value = args.get(arg.name)
        if value is None:
            continue
        if arg.kind in ("str_list", "vector"):
            value = tuple(value)
        elif arg.kind == "matrix4":
            value = tuple(tuple(row) for row in value)
        values[arg.name] = value
    return cls(**values)


def split_items(text: str) -> tuple[str, ...]:
    """A list argument typed as `red, blue`: its items, stripped, empty ones left out."""
    return tuple(item.strip() for item in text.split(",") if item.strip())


def wire_args(request: Any) -> dict[str, Any]:
    """The protocol's `args` of a request record: each argument given (not None), tuples as
    JSON arrays; `build(type(request), wire_args(request))` gives the record back. None: no
    arguments (every default)."""
    out: dict[str, Any] = {}
    if request is None:
        return out
    for arg in args_of(type(request)):
        value = getattr(request, arg.name)
        if value is None:
            continue
        if arg.kind == "matrix4":
            value = [list(row) for row in value]
        elif isinstance(value, tuple):
            value = list(value)
        out[arg.name] = value
    return out


def _value_schema(arg: Arg) -> dict[str, Any]:
    """The schema of one argument's non-null value."""
    bounds = {k: v for k, v in (("minimum", arg.lo), ("maximum", arg.hi)) if v is not None}
    number = {"type": "number", **bounds}
    if arg.kind == "bool":
        return {"type": "boolean"}
    if arg.kind == "int":
        return {"type": "integer", **bounds}
    if arg.kind == "number":
        return number
    if arg.kind in ("str", "path"):
        text: dict[str, Any] = {"type": "string", "minLength": 1, "maxLength": arg.max_chars}
        text["pattern"] = "^/[^\\x00]*$" if arg.kind == "path" else "^[^\\x00]*$"
        if arg.choices:
            text["enum"] = list(arg.choices)
        return text
    if arg.kind == "str_list":
        item = {"type": "string", "minLength": 1, "maxLength": MAX_ITEM_CHARS}
        return {"type": "array", "items": item, "minItems": 1, "maxItems": MAX_LIST_ITEMS}
    if arg.kind == "vector":
        return {"type": "array", "items": number, "minItems": arg.length, "maxItems": arg.length}
    row = {"type": "array", "items": number, "minItems": 4, "maxItems": 4}
    return {"type": "array", "items": row, "minItems": 4, "maxItems": 4}


def _property(arg: Arg) -> dict[str, Any]:
    value = _value_schema(arg)
    prop: dict[str, Any] = {"description": arg.help} if arg.help else {}
    if arg.required:
        prop.update(value)
    else:
        prop["anyOf"] = [value, {"type": "null"}]
        if arg.default is not None:
            prop["default"] = arg.default
    if arg.unit:
        prop["x-unit"] = arg.unit
    prop["x-kind"] = arg.kind
    return prop


def _condition_schema(condition: Condition) -> dict[str, Any]:
    other, values = condition
    given = {"not": {"type": "null"}}
    if isinstance(values, _Given):
        return {"required": [other], "properties": {other: given}}
    prop = {"enum": list(values)}
    if None in values:
        return {"properties": {other: prop}}
    return {"required": [other], "properties": {other: prop}}


def _all(conditions: tuple[Condition, ...]) -> dict[str, Any]:
    parts = [_condition_schema(c) for c in conditions]
    return parts[0] if len(parts) == 1 else {"allOf": parts}


def schema_of(cls: type[RequestClass] | None, title: str, description: str = "") -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the arguments object of the request `cls` (None: a
    command without arguments): each argument's type, bounds, choices, default, help
    (`description`) and unit (`x-unit`), and the rules between arguments as `if`/`then` and
    `oneOf`."""
    declared = args_of(cls) if cls is not None else ()
    rules: list[dict[str, Any]] = []
    for arg in declared:
        if arg.required_when:
            needed = {"required": [arg.name], "properties": {arg.name: {"not": {"type": "null"}}}}
            rules.append({"if": _all(arg.required_when), "then": needed})
        for condition in arg.only_when:
            absent = {"properties": {arg.name: {"type": "null"}}}
            rules.append({"if": {"not": _condition_schema(condition)}, "then": absent})
    group: tuple[str, ...] = getattr(cls, "EXACTLY_ONE", ())
    if group:
        given = {"not": {"type": "null"}}
        rules.append({"oneOf": [{"required": [k], "properties": {k: given}} for k in group]})
    schema: dict[str, Any] = {
        "$schema": SCHEMA_DIALECT,
        "title": title,
        "description": description,
        "type": "object",
        "properties": {a.name: _property(a) for a in declared},
        "required": [a.name for a in declared if a.required],
        "additionalProperties": False,
    }
    if rules:
        schema["allOf"] = rules
    return schema


def summary_line(cls: type[Any]) -> str:
    """The first paragraph of a request's docstring, on one line: the help of its command."""
    return " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
