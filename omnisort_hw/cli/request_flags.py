"""A command's flags made from its request record (`pipeline.requests`), and the request made
back from the parsed flags, with the same checks as the protocol's (`request_fields`).

The CLI declares by hand only what belongs to its door: which files to read and write
(`--system`, `--config`, `--out`, `--json`, `--log`); every argument of the use case comes from
the record. `image` is a positional argument, a bool a switch, a list or a vector comma
separated.
"""

from __future__ import annotations

import argparse
from collections.abc import Collection, Mapping
from typing import Any, TypeVar

from omnisort_hw.request_fields import (
    Arg,
    RequestClass,
    args_of,
    build,
    check_rules,
    check_value,
    condition_text,
    split_items,
)


def _holds_fixed(arg: Arg, fixed: Mapping[str, object]) -> bool:
    """False when `arg` is only for other values of a fixed argument (intrinsics' `degree` on
    the extrinsics command)."""
    for other, values in arg.only_when:
        if other in fixed and isinstance(values, tuple) and fixed[other] not in values:
            return False
    return True


def cli_args(
    cls: type[RequestClass], fixed: Mapping[str, object] = {}, skip: Collection[str] = ()
) -> list[Arg]:
    """The arguments of `cls` a CLI command offers: all but the fixed, the skipped and those
    that only apply to other values of a fixed one."""
    return [
        a
        for a in args_of(cls)
        if a.name not in fixed and a.name not in skip and _holds_fixed(a, fixed)
    ]


def _help(arg: Arg, default: Any, offered: Collection[str]) -> str:
    """The flag's help; a rule is said when it names another flag of the command."""
    text = arg.help + (f" ({arg.unit})" if arg.unit else "")
    if default is not None and arg.kind != "bool":
        text += f" (default {default})"
    rules = [condition_text(c) for c in arg.only_when if c[0] in offered]
    if rules:
        text += "; only " + " and ".join(rules)
    return text.replace("%", "%%")


def split_numbers(text: str) -> list[float]:
    """A vector flag's `a,b,c` as numbers (their count and bounds are the declaration's to
    check)."""
    try:
        return [float(item) for item in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"comma-separated numbers, got {text!r}") from None


def add_request_arguments(
    parser: argparse.ArgumentParser,
    cls: type[RequestClass],
    *,
    fixed: Mapping[str, object] = {},
    skip: Collection[str] = (),
    defaults: Mapping[str, object] = {},
) -> None:
    """Add a flag per argument of `cls` (`cli_args`). `defaults` are this door's own defaults
    where they differ from the record's (the CLI draws a map's picture unless told not to).
    A flag left out parses as None: the record's default."""
    offered = cli_args(cls, fixed, skip)
    names = {a.name for a in offered}
    for arg in offered:
        default = defaults.get(arg.name, arg.default)
        kw: dict[str, Any] = {"default": defaults.get(arg.name), "help": _help(arg, default, names)}
        if not arg.cli_flag.startswith("-"):
            parser.add_argument(arg.name, nargs="?", **kw)
            continue
        if arg.kind == "bool":
            on_off = default is not False
            kw["action"] = argparse.BooleanOptionalAction if on_off else "store_true"
        elif arg.kind in ("int", "number"):
            kw["type"] = int if arg.kind == "int" else float
        elif arg.kind == "str_list":
            kw.update(type=split_items, metavar="A,B,...")
        elif arg.kind == "vector":
            kw.update(type=split_numbers, metavar=",".join(["N"] * (arg.length or 1)))
        elif arg.kind == "matrix4":
            raise TypeError(f"{arg.name}: no use case's CLI has a 4x4 matrix argument")
        if arg.choices:
            kw["choices"] = arg.choices
        parser.add_argument(arg.cli_flag, dest=arg.name, **kw)


R = TypeVar("R", bound=RequestClass)


def request_from(
    cls: type[R],
    args: argparse.Namespace,
    command: str,
    *,
    fixed: Mapping[str, object] = {},
    skip: Collection[str] = (),
) -> R:
    """The request `cls` of the parsed flags (and `fixed`), checked as the protocol checks it
    (bounds, lengths, the rules between arguments); InputError names the flag. `skip`: the
    arguments this command gives in its own way (never missing)."""
    values: dict[str, Any] = dict(fixed)
    labels: dict[str, str] = {}
    for arg in cli_args(cls, fixed, skip):
        labels[arg.name] = arg.cli_flag
        value = getattr(args, arg.name)
        if value is not None:
            values[arg.name] = check_value(
                arg, command, value, label=arg.cli_flag, cell_paths=False
            )
    check_rules(cls, command, values, labels, supplied=skip)
    request: R = build(cls, values)
    return request
