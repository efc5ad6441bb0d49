"""The declaration layer measured both ways (docs/architecture.md, "One declaration"): the
project's `request_fields` (each request a dataclass whose fields carry `param()` metadata;
checks, JSON Schema and CLI flags made from it) against pydantic v2 models made from the very
same declarations (`pydantic.create_model`: bounds, choices, lengths, strict types, unknown
arguments forbidden; the rules between arguments as a model validator calling
`request_fields.check_rules`, which a migration would have to write again per model).

Measured, each in fresh interpreters where it is start-up (the minimum of several runs: the
machine's other load only adds):
- the CLI's start-up (`omnisort --help`) and whether it imports pydantic today;
- importing pydantic, and making every command's model;
- validating a request: `check_args` + `build` against `model_validate`, per request;
- the JSON Schema of every command: `schema_of` against `model_json_schema`;
- agreement: of the argument mutations the declarations refuse (wrong type, beyond a bound,
  not a choice, empty, wrong length), how many the models refuse too.
"""

from __future__ import annotations

import math
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Annotated, Any, Literal

from omnisort_hw.request_fields import (
    MAX_ITEM_CHARS,
    MAX_LIST_ITEMS,
    Arg,
    ArgumentError,
    args_of,
    build,
    check_args,
    check_rules,
    schema_of,
)
from omnisort_hw.service.protocol import COMMANDS
from omnisort_hw.sim_requests import SIM_COMMANDS

RUNS = 7  # fresh interpreters per start-up figure
REPEATS = 2000  # validations per request
CLI_HELP = """import sys, runpy
sys.argv = ["omnisort", "--help"]
try:
    runpy.run_module("omnisort_hw.cli", run_name="__main__")
except SystemExit:
    pass"""


def _declared() -> dict[str, type[Any]]:
    """Every request record of the service and the control channel, by command."""
    out = {name: c.request for name, c in COMMANDS.items() if c.request is not None}
    out |= {f"sim.{name}": c.request for name, c in SIM_COMMANDS.items() if c.request is not None}
    return out


def _annotation(arg: Arg) -> Any:
    """The pydantic type of one declared argument."""
    from pydantic import Field, StrictBool, StrictStr, StringConstraints

    def number(strict_int: bool = False) -> Any:
        base = int if strict_int else float
        return Annotated[base, Field(ge=arg.lo, le=arg.hi, allow_inf_nan=False)]

    text = Annotated[
        StrictStr, StringConstraints(min_length=1, max_length=arg.max_chars, pattern=r"^[^\x00]*$")
    ]
    kinds: dict[str, Any] = {
        "bool": StrictBool,
        "int": number(strict_int=True),
        "number": number(),
        "str": Literal[tuple(arg.choices)] if arg.choices else text,  # type: ignore[misc]
        "path": text,
        "str_list": Annotated[
            list[Annotated[StrictStr, StringConstraints(min_length=1, max_length=MAX_ITEM_CHARS)]],
            Field(min_length=1, max_length=MAX_LIST_ITEMS),
        ],
        "vector": Annotated[list[number()], Field(min_length=arg.length, max_length=arg.length)],
        "matrix4": Annotated[
            list[Annotated[list[number()], Field(min_length=4, max_length=4)]],
            Field(min_length=4, max_length=4),
        ],
    }
    return kinds[arg.kind]


def pydantic_model(cls: type[Any], command: str) -> Any:
    """The pydantic v2 model of a request record's declaration."""
    from pydantic import ConfigDict, Field, create_model, model_validator

    fields: dict[str, Any] = {}
    for arg in args_of(cls):
        t = _annotation(arg)
        if arg.required:
            fields[arg.name] = (t, Field(description=arg.help))
        else:
            fields[arg.name] = (t | None, Field(arg.default, description=arg.help))

    def rules(model: Any) -> Any:
        check_rules(cls, command, model.model_dump())
        return model

    return create_model(  # type: ignore[call-overload]
        cls.__name__,
        __config__=ConfigDict(extra="forbid"),
        __validators__={"rules": model_validator(mode="after")(rules)},
        **fields,
    )


def _fresh_ms(code: str) -> float:
    """The least wall time of RUNS fresh interpreters running `code`, in ms."""
    times = []
    for _ in range(RUNS):
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return 1000.0 * min(times)


def _mutations(arg: Arg) -> list[Any]:
    """Values the declaration refuses for `arg`."""
    bad: list[Any] = [{"a": 1}]
    if arg.kind == "bool":
        bad += [1, "true"]
    elif arg.kind in ("int", "number"):
        bad += ["1", True, math.nan, math.inf]
        bad += [arg.lo - 1.0] if arg.lo is not None else []
        bad += [arg.hi + 1.0] if arg.hi is not None else []
        bad += [0.5] if arg.kind == "int" else []
    elif arg.kind in ("str", "path"):
        bad += ["", 3, "a\x00b", "x" * (arg.max_chars + 1)]
        bad += ["not-a-choice"] if arg.choices else []
    elif arg.kind == "str_list":
        bad += [[], ["a"] * (MAX_LIST_ITEMS + 1), [""], [3], "a"]
    elif arg.kind == "vector":
        n = arg.length or 1
        bad += [[0.0] * (n + 1), ["a"] * n, 1.0]
    else:
        bad += [[[0.0] * 4] * 3, [[0.0] * 3] * 4, [["a"] * 4] * 4]
    return bad


def _valid(cls: type[Any], command: str) -> dict[str, Any] | None:
    """A request the declaration takes: the required arguments at a value in bounds."""
    raw: dict[str, Any] = {}
    for arg in args_of(cls):
        if not arg.required:
            continue
        if arg.choices:
            raw[arg.name] = arg.choices[0]
        elif arg.kind in ("int", "number"):
            raw[arg.name] = arg.lo if arg.lo is not None else 1
        elif arg.kind == "bool":
            raw[arg.name] = True
        elif arg.kind in ("str", "path"):
            raw[arg.name] = "/tmp/x"
        elif arg.kind == "vector":
            raw[arg.name] = [0.0] * (arg.length or 1)
        else:
            return None
    try:
        check_args(cls, command, raw)
    except ArgumentError:
        return None
    return raw


def _per_request_us(fn: Any, raws: list[dict[str, Any]]) -> float:
    """The median over the requests of each one's mean validation time, in microseconds."""
    per = []
    for raw in raws:
        t0 = time.perf_counter()
        for _ in range(REPEATS):
            fn(raw)
        per.append(1e6 * (time.perf_counter() - t0) / REPEATS)
    return statistics.median(per)


def run(shared: Path) -> dict[str, Any]:
    from pydantic import ValidationError

    declared = _declared()
    out: dict[str, Any] = {"requests": len(declared)}
    imported = subprocess.run(
        [sys.executable, "-c", CLI_HELP + "\nsys.stderr.write(str('pydantic' in sys.modules))"],
        capture_output=True,
        text=True,
    )
    out["cli_imports_pydantic"] = imported.stderr.strip().endswith("True")
    bare = _fresh_ms("pass")
    out["python_start_ms"] = round(bare, 1)
    out["cli_help_ms"] = round(_fresh_ms(CLI_HELP), 1)
    out["import_declarations_ms"] = round(
        _fresh_ms("import omnisort_hw.service.protocol, omnisort_hw.sim_requests") - bare, 1
    )
    out["import_pydantic_ms"] = round(_fresh_ms("import pydantic") - bare, 1)

    t0 = time.perf_counter()
    models = {name: pydantic_model(cls, name) for name, cls in declared.items()}
    out["make_models_ms"] = round(1000 * (time.perf_counter() - t0), 1)

    t0 = time.perf_counter()
    for name, cls in declared.items():
        schema_of(cls, name)
    out["schema_ms_request_fields"] = round(1000 * (time.perf_counter() - t0), 2)
    t0 = time.perf_counter()
    for model in models.values():
        model.model_json_schema()
    out["schema_ms_pydantic"] = round(1000 * (time.perf_counter() - t0), 2)

    valid = {n: r for n, cls in declared.items() if (r := _valid(cls, n)) is not None}
    out["valid_requests_timed"] = len(valid)

    def ours(item: tuple[str, dict[str, Any]]) -> Any:
        name, raw = item
        return build(declared[name], check_args(declared[name], name, raw))

    def theirs(item: tuple[str, dict[str, Any]]) -> Any:
        name, raw = item
        return models[name].model_validate(raw)

    items: list[Any] = list(valid.items())
    out["validate_us_request_fields"] = round(_per_request_us(ours, items), 1)
    out["validate_us_pydantic"] = round(_per_request_us(theirs, items), 1)

    refused = missed = 0
    missed_kinds: dict[str, int] = {}
    for name, raw in valid.items():
        cls = declared[name]
        for arg in args_of(cls):
            for value in _mutations(arg):
                bad = {**raw, arg.name: value}
                try:
                    check_args(cls, name, bad)
                    continue  # the declaration takes it: not a mutation of this argument
                except ArgumentError:
                    refused += 1
                try:
                    models[name].model_validate(bad)
                    missed += 1
                    missed_kinds[arg.kind] = missed_kinds.get(arg.kind, 0) + 1
                except (ValidationError, ArgumentError):
                    pass
    out["mutations_refused_by_declarations"] = refused
    out["mutations_taken_by_pydantic_models"] = missed
    out["taken_by_kind"] = dict(sorted(missed_kinds.items()))
    return out
