"""The `omnisort` command line. Each command group lives in its own module with `register()`."""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections.abc import Sequence

from omnisort_hw.errors import OmnisortError

# Each module defines `register(subparsers)` and sets `func` on its parsers; `func(args)`
# returns the exit code. Heavy imports stay inside the command functions.
COMMAND_MODULES: tuple[str, ...] = (
    "omnisort_hw.cli.intrinsics_cmd",
    "omnisort_hw.cli.extrinsics_cmd",
    "omnisort_hw.cli.robot_cmd",
    "omnisort_hw.cli.evaluate_cmd",
    "omnisort_hw.cli.demo_cmd",
    "omnisort_hw.cli.serve_cmd",
    "omnisort_hw.cli.ctl_cmd",
    "omnisort_hw.cli.review_cmd",
    "omnisort_hw.cli.devices_cmd",
    "omnisort_hw.cli.sim_cmd",
    "omnisort_hw.cli.drift_cmd",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="omnisort", description="Fisheye camera + laser-plane robotic sorting cell."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def report_error(args: argparse.Namespace, code: str, message: str) -> None:
    """The error on stderr for people and, for a `--json` command, on stdout in the service's
    error shape (`{"ok": false, "error": {"code", "message"}}`) so scripts always get JSON."""
    print(f"omnisort: error [{code}]: {message}", file=sys.stderr)
    if getattr(args, "json", False) is True:
        print(json.dumps({"ok": False, "error": {"code": code, "message": message}}))


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except OmnisortError as exc:
        report_error(args, exc.code, str(exc))
        return exc.exit_code
    except KeyboardInterrupt:
        report_error(args, "interrupted", "interrupted")
        return 130
    except Exception as exc:
        # Device errors live in drivers/ and do not derive from OmnisortError; any class with
        # a `code` attribute is one of ours and gets the same treatment.
        code = getattr(exc, "code", None)
        if isinstance(code, str):
            report_error(args, code, str(exc))
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
