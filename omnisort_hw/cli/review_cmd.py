"""`omnisort review FILE [--list]`: open a run's `.rrd` file in the rerun viewer."""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    p = sub.add_parser(
        "review",
        help="open a run's .rrd file in the rerun viewer (or --list its entities)",
    )
    p.add_argument("file", type=Path, help="an .rrd file written by the service or a command")
    p.add_argument("--list", action="store_true", help="print the entity paths and exit")
    p.set_defaults(func=run)


def viewer_command() -> list[str]:
    """The rerun viewer: $OMNISORT_RERUN, else `rerun` beside this Python, else on PATH."""
    override = os.environ.get("OMNISORT_RERUN")
    if override:
        return override.split()
    beside = Path(sys.executable).parent / "rerun"
    if beside.exists():
        return [str(beside)]
    found = shutil.which("rerun")
    if found:
        return [found]
    from omnisort_hw.errors import ConfigError

    raise ConfigError("the rerun viewer was not found (install rerun-sdk in this environment)")


def run(args: argparse.Namespace) -> int:
    from omnisort_hw.errors import InputError

    path: Path = args.file
    if not path.is_file():
        raise InputError(f"{path}: no such .rrd file")
    if args.list:
        from omnisort_hw.runlog import entity_paths

        try:
            paths = entity_paths(path)
        except Exception as exc:
            raise InputError(f"{path}: not a readable .rrd file ({exc})") from None
        for entity in sorted(paths):
            print(entity)
        return 0
    # The viewer is interactive: it runs until the user closes it.
    return subprocess.call([*viewer_command(), str(path)])
