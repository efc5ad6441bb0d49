"""The `omnisort` command line. Each command group lives in its own module with `register()`."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import NoReturn

from omnisort_hw.cli.output import print_error, report_error
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


class Parser(argparse.ArgumentParser):
    """argparse, but a command line refused while parsing (a bad value, an output that is a
    folder) is also JSON on stdout when `--json` is among the arguments."""

    def error(self, message: str) -> NoReturn:
        if "--json" in _ARGV:
            print_error("bad_input", message)
        super().error(message)


_ARGV: list[str] = []  # the command line main() parses


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="omnisort", description="Fisheye camera + laser-plane robotic sorting cell."
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    _ARGV[:] = list(argv) if argv is not None else sys.argv[1:]
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except OmnisortError as exc:
        report_error(getattr(args, "json", False) is True, exc.code, str(exc))
        return exc.exit_code
    except KeyboardInterrupt:
        report_error(getattr(args, "json", False) is True, "interrupted", "interrupted")
        return 130
    except Exception as exc:
        # Device errors live in drivers/ and do not derive from OmnisortError; any class with
        # a `code` attribute is one of ours and gets the same treatment.
        code = getattr(exc, "code", None)
        if isinstance(code, str):
            report_error(getattr(args, "json", False) is True, code, str(exc))
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
