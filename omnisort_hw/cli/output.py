"""What `--json` commands print: one shape for every command, the protocol's without the id.
A result is `{"ok": true, "result": {...}}`, an error `{"ok": false, "error": {"code",
"message"}}`, so a script reads every command (and `ctl`'s replies) the same way."""

from __future__ import annotations

import json
import sys

from omnisort_hw.wire_records import to_wire

EXIT_DRIFT = 4
"""`omnisort check` and `omnisort ctl check`: the check ran and found the camera turned (0: it
did not; errors keep their own codes), so a script can stop the line on it."""


def print_result(result: object, indent: int | None = None) -> None:
    """A command's result (a reply's record, or its JSON object) as one JSON document on
    stdout (NaN as null, as on the protocol: strict JSON parsers refuse NaN)."""
    from omnisort_hw.service.protocol import encode

    doc = json.loads(encode({"ok": True, "result": to_wire(result)}))
    print(json.dumps(doc, indent=indent))


def print_verdict(result: object) -> None:
    """A reply's verdict and its picture, as the last lines of a command's human output."""
    from omnisort_hw.core.records import PictureReply
    from omnisort_hw.pipeline.verdict import verdict_lines, verdict_of

    if isinstance(result, PictureReply):
        if result.overlay_png:
            print(f"picture: {result.overlay_png}")
        elif result.overlay_problem:
            print(f"no picture: {result.overlay_problem}")
    verdict = verdict_of(result)
    if verdict is not None:
        print("\n".join(verdict_lines(verdict)))


def print_error(code: str, message: str) -> None:
    """A command's error as one JSON document on stdout."""
    print(json.dumps({"ok": False, "error": {"code": code, "message": message}}))


def report_error(json_requested: bool, code: str, message: str) -> None:
    """The error on stderr for people and, when `--json` was given, on stdout as JSON."""
    print(f"omnisort: error [{code}]: {message}", file=sys.stderr)
    if json_requested:
        print_error(code, message)
