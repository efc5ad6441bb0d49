"""Replies as typed records, one codec for all of them: a reply declared once as a frozen
dataclass is written to JSON by `to_wire` (where a door sends it) and read back by
`from_wire` (where a client reads it), so the service builds fields, the page reads fields,
and neither names a key.

The codec reads each record's own annotations (`typing.get_type_hints`): nested records,
`list[T]`, `tuple[T, ...]` and fixed tuples, `dict[str, T]`, `T | None`, `Literal[...]`,
numbers (an int is a valid float, as in JSON; a null where a float is declared is NaN, which
strict JSON cannot carry and the protocol sends as null), and `Any` or `dict[str, Any]` as
they come.
- A field made with `absent()` is left out of the JSON while it holds its default (None, or
  the default given), as a key that is not always there; a field with `None` in its type and
  no `absent()` is sent as null.
- A field made with `wire_key(key)` is sent under `key` (a Python keyword: `from`).
- A field with `init=False` (a figure the record computes from its other fields) is sent, and
  computed again when read.
- A reply that does not fit its record raises `WireError` naming the record and the field's
  path (`GeometryReply.laser_plane.normal[2]`).

This module imports nothing of the project's numerics, so a client reads replies at no
start-up cost.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
from collections.abc import Mapping
from typing import Any, Literal, TypeVar, Union, cast, get_args, get_origin, get_type_hints

from omnisort_hw.errors import OmnisortError

T = TypeVar("T")

_ABSENT = "wire_absent"
_KEY = "wire_key"
_SCALARS = (float, int, str, bool, type(None))
_KIND_NAMES: dict[Any, str] = {
    bool: "true or false",
    int: "an integer",
    float: "a number",
    str: "a string",
    type(None): "null",
}


class WireError(OmnisortError, ValueError):
    """A reply that does not fit its record: `path` names the record and the field."""

    def __init__(self, path: str, problem: str) -> None:
        self.path, self.problem = path, problem
        super().__init__(f"{path}: {problem}")


def wire_key(key: str) -> Any:
    """A field sent under another key than its name (a key that is a Python keyword)."""
    return dataclasses.field(metadata={_KEY: key})


def absent(default: Any = None) -> Any:
    """A field whose key a reply leaves out while it holds `default` (a `NotRequired` key);
    `default` is None or an immutable value."""
    return dataclasses.field(default=default, metadata={_ABSENT: True})


def to_wire(value: object) -> Any:
    """A record (and the records, tuples and mappings it holds) as plain JSON values; a field
    made with `absent()` is left out while it holds its default. Anything else is returned as
    it is."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        out: dict[str, Any] = {}
        for f in dataclasses.fields(value):
            v = getattr(value, f.name)
            if f.metadata.get(_ABSENT) and v == f.default:
                continue
            out[f.metadata.get(_KEY, f.name)] = to_wire(v)
        return out
    if isinstance(value, list | tuple):
        if all(type(v) in _SCALARS for v in value):  # points, names: as they are
            return list(value)
        return [to_wire(v) for v in value]
    if isinstance(value, Mapping):
        return {k: to_wire(v) for k, v in value.items()}
    return value


def from_wire(cls: type[T], data: Any) -> T:
    """`data` (a reply's JSON) read as the record `cls`; WireError names what does not fit."""
    return cast(T, _read(cls, data, cls.__name__))


def read_value(tp: Any, data: Any, path: str) -> Any:
    """`data` read as the annotation `tp` (a record, a list, a number...); WireError names
    `path` (a cell file's `[laser].baudrate`) and what does not fit. The cell file's device
    sections are read with it too."""
    return _read(tp, data, path)


def kind_name(tp: Any) -> str:
    """What a value of the annotation `tp` is, in words for a message."""
    origin, args = _shape(tp)
    if origin is Union or origin is types.UnionType:
        return " or ".join(kind_name(a) for a in args)
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (list, tuple):
        return "a list of numbers" if args and args[0] in (float, int) else "a list"
    if origin is dict or (isinstance(tp, type) and dataclasses.is_dataclass(tp)):
        return "an object"
    return _KIND_NAMES.get(tp, str(tp))


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return get_type_hints(cls)


@functools.cache
def _shape(tp: Any) -> tuple[Any, tuple[Any, ...]]:
    return get_origin(tp), get_args(tp)


def _read(tp: Any, data: Any, path: str) -> Any:
    if tp is Any:
        return data
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return _read_record(tp, data, path)
    origin, args = _shape(tp)
    if origin is Union or origin is types.UnionType:
        if data is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _read(inner[0], data, path)
        for a in inner:  # the first that fits, as written
            try:
                return _read(a, data, path)
            except WireError:
                continue
        raise WireError(path, f"must be {kind_name(tp)}, got {_shown(data)}")
    if origin is Literal:
        if data not in args:
            raise WireError(path, f"must be {kind_name(tp)}, got {_shown(data)}")
        return data
    if origin in (list, tuple):
        if not isinstance(data, list | tuple):
            raise WireError(path, f"must be {kind_name(tp)}, got {_shown(data)}")
        if origin is tuple and not (len(args) == 2 and args[1] is Ellipsis) and args:
            if len(args) != len(data):
                raise WireError(path, f"must be {len(args)} values, got {len(data)}")
            return tuple(
                _read(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, data, strict=True))
            )
        item = args[0] if args else Any
        if item is float and all(type(v) in (float, int) for v in data):  # points: at once
            read = [float(v) for v in data]
        else:
            read = [_read(item, v, f"{path}[{i}]") for i, v in enumerate(data)]
        return read if origin is list else tuple(read)
    if origin is dict:
        if not isinstance(data, Mapping):
            raise WireError(path, f"must be an object, got {_shown(data)}")
        value_type = args[1] if len(args) == 2 else Any
        return {str(k): _read(value_type, v, f"{path}.{k}") for k, v in data.items()}
    return _read_scalar(tp, data, path)


def _read_record(cls: type, data: Any, path: str) -> Any:
    if not isinstance(data, Mapping):
        raise WireError(path, f"must be an object, got {_shown(data)}")
    hints, values = _hints(cls), {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        key = f.metadata.get(_KEY, f.name)
        if key in data:
            values[f.name] = _read(hints[f.name], data[key], f"{path}.{key}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise WireError(f"{path}.{key}", "missing")
    return cls(**values)


def _read_scalar(tp: Any, data: Any, path: str) -> Any:
    if tp is float:
        if isinstance(data, int | float) and not isinstance(data, bool):
            return float(data)
        if data is None:  # strict JSON has no NaN: the protocol sends it as null
            return math.nan
    elif tp is int:
        if isinstance(data, int) and not isinstance(data, bool):
            return data
    elif tp in (str, bool):
        if type(data) is tp:
            return data
    elif tp is type(None):
        if data is None:
            return None
    else:
        raise WireError(path, f"cannot be read as {tp}")
    raise WireError(path, f"must be {kind_name(tp)}, got {_shown(data)}")


def _shown(data: Any) -> str:
    text = repr(data)
    return (text if len(text) <= 40 else text[:37] + "...") + f" ({type(data).__name__})"
