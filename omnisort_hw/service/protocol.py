"""The control protocol: one JSON object per line each way, validated field by field.

Request:  {"id": 7, "cmd": "status", "args": {...}, "token": "..."}
Reply:    {"id": 7, "ok": true, "result": {...}}
          {"id": 7, "ok": false, "error": {"code": "...", "message": "...", ...}}

`parse_request` never raises anything but `ProtocolError`, whatever the bytes are, so the server
can answer every line with a typed error. Each command's arguments are declared once, in its
request record (`pipeline.requests`: type, range, length, choices, default, the rules between
them); `COMMANDS` names the record, and unknown arguments are refused.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from omnisort_hw.pipeline import requests
from omnisort_hw.pipeline.replies import CommandDescription, DescribeReply
from omnisort_hw.request_fields import (
    SCHEMA_DIALECT,
    Arg,
    ArgumentError,
    args_of,
    build,
    check_args,
    schema_of,
    summary_line,
    type_name,
)
from omnisort_hw.wire_records import to_wire

# Error codes of the protocol. Typed errors of the product and of the drivers keep their own
# `code` inside `details` where it says more (e.g. device_timeout, bad_calibration_file).
BAD_JSON = "bad_json"
BAD_REQUEST = "bad_request"
UNKNOWN_COMMAND = "unknown_command"
BAD_ARGUMENT = "bad_argument"
UNAUTHORIZED = "unauthorized"
BUSY = "busy"
MOTION_REFUSED = "motion_refused"
DEVICE_ERROR = "device_error"
NOT_AVAILABLE = "not_available"
STOPPED = "stopped"
INTERNAL = "internal"
ERROR_CODES: tuple[str, ...] = (
    BAD_JSON,
    BAD_REQUEST,
    UNKNOWN_COMMAND,
    BAD_ARGUMENT,
    UNAUTHORIZED,
    BUSY,
    MOTION_REFUSED,
    DEVICE_ERROR,
    NOT_AVAILABLE,
    STOPPED,
    INTERNAL,
    # Product errors passed through with their own code (omnisort_hw.errors).
    "bad_input",
    "bad_config",
    "calibration_failed",
    "feature_not_found",
    "bad_calibration_file",
    "storage_error",
    "io_error",
    "gripper_loaded",
    "instance_locked",
    "calibration_drift",
    "not_registered",
    "no_laser_line",
)

MAX_ID_CHARS = 128
MAX_JSON_DEPTH = 16
MAX_ID_INT = 2**53

CommandKind = Literal["quick", "job", "safety", "control"]


class ProtocolError(Exception):
    """A request that cannot be served; `code` is one of ERROR_CODES."""

    def __init__(self, code: str, message: str, **details: Any) -> None:
        super().__init__(message)
        self.code = code
        self.message = message
        self.details = details


@dataclass(frozen=True)
class Command:
    """A command: its arguments, how it runs, whether it needs the token off loopback."""

    name: str
    kind: CommandKind
    request: type[Any] | None = None  # the request record that declares the arguments
    needs_token: bool = True
    job_state: str | None = None
    help: str = ""

    @property
    def args(self) -> tuple[Arg, ...]:
        return args_of(self.request) if self.request is not None else ()

    @property
    def summary(self) -> str:
        return self.help or (summary_line(self.request) if self.request is not None else "")

    def arg(self, name: str) -> Arg | None:
        return next((a for a in self.args if a.name == name), None)

    def schema(self) -> dict[str, Any]:
        """The JSON Schema (draft 2020-12) of this command's `args` object."""
        return schema_of(self.request, self.name, self.summary)

    def describe(self) -> CommandDescription:
        """What a client needs to offer this command: how it runs, and its arguments."""
        return CommandDescription(
            self.kind, self.needs_token, self.job_state, self.summary, self.schema()
        )


@dataclass(frozen=True)
class Request:
    """A validated request. `args` holds every declared argument (defaults filled in)."""

    id: int | str | None
    cmd: str
    args: dict[str, Any] = field(default_factory=dict)
    token: str | None = None
    progress: bool = False  # the client asked for progress events before a job's reply

    @property
    def command(self) -> Command:
        return COMMANDS[self.cmd]

    @property
    def payload(self) -> Any:
        """The command's request record built from `args` (None for a command without one)."""
        request = self.command.request
        return build(request, self.args) if request is not None else None


COMMANDS: dict[str, Command] = {
    c.name: c
    for c in (
        Command("status", "quick", needs_token=False, help="state, devices and calibration"),
        Command(
            "describe",
            "quick",
            help="each command's kind and the JSON Schema (draft 2020-12) of its arguments",
        ),
        Command("view", "quick", requests.ViewRequest, needs_token=False),
        Command("picture", "quick", requests.PictureRequest),
        Command("detect", "quick", requests.DetectRequest),
        Command("views", "quick", requests.ViewsRequest),
        Command("history", "quick", requests.HistoryRequest),
        Command("geometry", "quick", requests.GeometryRequest, needs_token=False),
        Command("capture", "quick", requests.CaptureRequest),
        Command("laser", "quick", requests.LaserRequest),
        Command("calibrate", "job", requests.CalibrateRequest, job_state="calibrating"),
        Command("map", "job", requests.MapRequest, job_state="mapping"),
        Command("register_robot", "job", requests.RegisterRequest, job_state="calibrating"),
        Command("locate", "job", requests.LocateRequest, job_state="mapping"),
        Command("move", "job", requests.MoveRequest, job_state="moving"),
        Command("sort", "job", requests.SortRequest, job_state="sorting"),
        Command("check", "job", requests.CheckRequest, job_state="mapping"),
        Command("adopt", "job", requests.AdoptRequest, job_state="calibrating"),
        Command(
            "acknowledge_drift",
            "quick",
            help="accept a detected calibration drift: motion allowed again",
        ),
        Command("stop", "safety", needs_token=False, help="stop the running job and the arm"),
        Command(
            "estop",
            "safety",
            needs_token=False,
            help="stop everything, laser off, latch the fault state (not a safety function)",
        ),
        Command("reset", "control", requests.ResetRequest),
        Command("shutdown", "control", help="stop the cell and end the service (exit 0)"),
    )
}


OPEN_COMMANDS = tuple(name for name, c in COMMANDS.items() if not c.needs_token)
"""The commands any client may send without the token: they read, or they stop."""


def describe_commands() -> DescribeReply:
    """The `describe` reply: every command, with its arguments' JSON Schema."""
    return DescribeReply(SCHEMA_DIALECT, {name: c.describe() for name, c in COMMANDS.items()})


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not valid JSON")


def _depth(obj: object, limit: int) -> int:
    """Nesting depth of a parsed JSON value, stopping once past `limit`."""
    stack: list[tuple[Any, int]] = [(obj, 1)]
    deepest = 0
    while stack:
        node, d = stack.pop()
        deepest = max(deepest, d)
        if deepest > limit:
            return deepest
        if isinstance(node, dict):
            stack.extend((v, d + 1) for v in node.values())
        elif isinstance(node, list):
            stack.extend((v, d + 1) for v in node)
    return deepest


def peek_id(obj: object) -> int | str | None:
    """The request id if it is a valid one (so even an error reply can carry it)."""
    if not isinstance(obj, dict):
        return None
    rid = obj.get("id")
    if isinstance(rid, bool):
        return None
    if isinstance(rid, int) and abs(rid) <= MAX_ID_INT:
        return rid
    if isinstance(rid, str) and len(rid) <= MAX_ID_CHARS:
        return rid
    return None


def decode_line(line: bytes) -> Any:
    """Bytes of one line to a JSON value; ProtocolError(bad_json) for anything else."""
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ProtocolError(BAD_JSON, f"request is not UTF-8 (byte {exc.start})") from None
    if not text.strip():
        raise ProtocolError(BAD_JSON, "empty request line")
    try:
        obj = json.loads(text, parse_constant=_reject_constant)
    except RecursionError:
        raise ProtocolError(BAD_JSON, f"request nested deeper than {MAX_JSON_DEPTH}") from None
    except ValueError as exc:
        raise ProtocolError(BAD_JSON, f"request is not valid JSON: {str(exc)[:160]}") from None
    if _depth(obj, MAX_JSON_DEPTH) > MAX_JSON_DEPTH:
        raise ProtocolError(BAD_JSON, f"request nested deeper than {MAX_JSON_DEPTH}")
    return obj


Authorizer = Callable[[Command, "str | None", "int | str | None"], None]
Emit = Callable[[dict[str, Any]], None]
"""Where a job's progress events go (in the loop thread), before its reply."""


def validate_request(obj: object, authorize: Authorizer | None = None) -> Request:
    """A decoded JSON value to a Request, checking every field; raises ProtocolError.

    `authorize(command, token, id)` runs once the command is known and before its arguments
    are looked at, so a client without the token learns nothing about them.
    """
    if not isinstance(obj, dict):
        raise ProtocolError(BAD_REQUEST, f"request must be a JSON object, got {type_name(obj)}")
    unknown = sorted(set(obj) - {"id", "cmd", "args", "token", "progress"})
    if unknown:
        shown = ", ".join(repr(k[:32]) for k in unknown[:5])
        raise ProtocolError(
            BAD_REQUEST,
            f"unknown request field(s) {shown}; allowed: id, cmd, args, token, progress",
        )
    progress = obj.get("progress", False)
    if not isinstance(progress, bool):
        raise ProtocolError(BAD_REQUEST, "'progress' must be true or false", field="progress")
    rid = obj.get("id")
    if rid is not None and peek_id(obj) is None:
        raise ProtocolError(
            BAD_REQUEST,
            f"id must be an integer (|id| <= 2^53) or a string of up to {MAX_ID_CHARS} chars",
            field="id",
        )
    cmd = obj.get("cmd")
    if cmd is None:
        raise ProtocolError(BAD_REQUEST, "missing field 'cmd'", field="cmd")
    if not isinstance(cmd, str):
        raise ProtocolError(
            BAD_REQUEST, f"'cmd' must be a string, got {type_name(cmd)}", field="cmd"
        )
    spec = COMMANDS.get(cmd)
    if spec is None:
        raise ProtocolError(
            UNKNOWN_COMMAND,
            f"unknown command {cmd[:40]!r}; known: {', '.join(COMMANDS)}",
            field="cmd",
        )
    token = obj.get("token")
    if token is not None and (not isinstance(token, str) or len(token) > 1024):
        raise ProtocolError(BAD_REQUEST, "'token' must be a string", field="token")
    if authorize is not None:
        authorize(spec, token, rid)
    raw_args = obj.get("args", {})
    if raw_args is None:
        raw_args = {}
    if not isinstance(raw_args, dict):
        raise ProtocolError(
            BAD_REQUEST, f"'args' must be an object, got {type_name(raw_args)}", field="args"
        )
    args = validate_args(spec, raw_args)
    return Request(id=rid, cmd=cmd, args=args, token=token, progress=progress)


def validate_args(spec: Command, raw: Mapping[str, object]) -> dict[str, Any]:
    """Check each argument of `spec` in `raw` (`request_fields.check_args`); unknown, missing
    or bad ones are bad_argument naming the field."""
    try:
        return check_args(spec.request, spec.name, raw)
    except ArgumentError as exc:
        raise ProtocolError(BAD_ARGUMENT, str(exc), field=exc.field) from None


def parse_request(line: bytes, authorize: Authorizer | None = None) -> Request:
    """One line of bytes (without the newline) to a validated (and authorised) Request."""
    obj = decode_line(line)
    try:
        return validate_request(obj, authorize)
    except ProtocolError as exc:
        exc.details.setdefault("id", peek_id(obj))
        raise


def _json_default(obj: object) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_wire(obj)  # a reply record a door forgot to write: its JSON, not its repr
    tolist = getattr(obj, "tolist", None)
    if callable(tolist):
        return tolist()
    if isinstance(obj, set | frozenset | tuple):
        return list(obj)
    return str(obj)


def encode(obj: Mapping[str, object]) -> bytes:
    """One reply line: compact JSON (numpy values converted, NaN as null) and a newline."""
    try:
        text = json.dumps(obj, separators=(",", ":"), default=_json_default, allow_nan=False)
    except ValueError:
        text = json.dumps(_denan(obj), separators=(",", ":"), default=_json_default)
    return text.encode("utf-8") + b"\n"


def _denan(obj: object) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, Mapping):
        return {str(k): _denan(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_denan(v) for v in obj]
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return _denan(to_wire(obj))
    tolist = getattr(obj, "tolist", None)
    if callable(tolist):
        return _denan(tolist())
    return obj


def ok_reply(rid: int | str | None, result: Mapping[str, object]) -> dict[str, Any]:
    return {"id": rid, "ok": True, "result": dict(result)}


def progress_event(rid: int | str | None, event: Mapping[str, object]) -> dict[str, Any]:
    """A line sent before a job's reply when the request asked for `progress`: it carries the
    request's id and no `ok`, so a client tells it from the reply."""
    return {"id": rid, "event": "progress", "progress": dict(event)}


def error_reply(rid: int | str | None, code: str, message: str, **details: Any) -> dict[str, Any]:
    error: dict[str, Any] = {"code": code, "message": message}
    error.update({k: v for k, v in details.items() if k != "id" and v is not None})
    return {"id": rid, "ok": False, "error": error}


def reply_for(exc: ProtocolError, rid: int | str | None = None) -> dict[str, Any]:
    """The error reply for a ProtocolError (its own id detail wins over `rid`)."""
    the_id = exc.details.get("id", rid)
    return error_reply(the_id, exc.code, exc.message, **exc.details)
