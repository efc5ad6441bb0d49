"""The `omnisort` command line. Each command group lives in its own module with `register()`."""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import NoReturn

from omnisort_hw.cli.output import print_error, report_error
from omnisort_hw.errors import IO_ERROR, OmnisortError
from omnisort_hw.fileio import os_error_text

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
    "omnisort_hw.cli.ui_cmd",
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
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a reader gone shows here, inside the handlers below
        return status
    except OmnisortError as exc:
        report_error(getattr(args, "json", False) is True, exc.code, str(exc))
        return exc.exit_code
    except KeyboardInterrupt:
        report_error(getattr(args, "json", False) is True, "interrupted", "interrupted")
        return 130
    except BrokenPipeError:
        return _reader_gone()
    except OSError as exc:
        # A file the command reads or writes failed in a way no check before could see (a
        # disk filled, a mount went away): the file and the OS error, never a traceback.
        report_error(getattr(args, "json", False) is True, IO_ERROR, os_error_text(exc))
        return 2
    except Exception as exc:
        # Device errors live in drivers/ and do not derive from OmnisortError; any class with
        # a `code` attribute is one of ours and gets the same treatment.
        code = getattr(exc, "code", None)
        if isinstance(code, str):
            report_error(getattr(args, "json", False) is True, code, str(exc))
            return 2
        raise


def _reader_gone() -> int:
    """stdout's reader has gone (`omnisort ctl status | head -1`): end quietly, as a Unix
    tool killed by SIGPIPE would (exit 141), with stdout sent to /dev/null so the
    interpreter's own flush at exit does not print a second error."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 141


if __name__ == "__main__":
    sys.exit(main())
