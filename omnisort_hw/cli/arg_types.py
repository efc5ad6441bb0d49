"""argparse types shared by the command modules: inputs checked when the command line is
parsed, before any device opens or any long computation starts."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TypeAlias

from omnisort_hw.fileio import output_file_problem, output_folder_problem

Subcommands: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"
"""What `add_subparsers()` returns: each command module's `register()` adds its parsers to it."""


def output_file(text: str) -> Path:
    """A file the command will write: not a folder, and in a folder that can be written."""
    problem = output_file_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return Path(text)


def output_folder(text: str) -> Path:
    """A folder the command will write into: not a file, and creatable or writable."""
    problem = output_folder_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return Path(text)
