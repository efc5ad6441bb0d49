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
    p.add_argument(
        "file", type=Path, nargs="?", help="an .rrd file written by the service or a command"
    )
    p.add_argument("--list", action="store_true", help="print the entity paths and exit")
    p.add_argument(
        "--live",
        metavar="HOST:PORT",
        default=None,
        help="watch a running service's live view ([logging] live) instead of a file",
    )
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


def live_url(address: str) -> str:
    """The viewer URL of a live view at HOST:PORT (a rerun+http URL is taken as it is)."""
    from omnisort_hw.errors import InputError

    if address.startswith(("rerun://", "rerun+http://", "rerun+https://")):
        return address
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"--live must be HOST:PORT (e.g. 127.0.0.1:9876), got {address!r}")
    return f"rerun+http://{host}:{int(port)}/proxy"


def save_live_command(address: str, out: Path) -> list[str]:
    """rerun's CLI saving what the live view at HOST:PORT sends into `out` (its own viewer
    server on a free loopback port): a separate process that watches the stream."""
    return [
        *viewer_command(),
        live_url(address),
        "--bind",
        "127.0.0.1",
        "--port",
        "0",
        "--save",
        str(out),
    ]


def run(args: argparse.Namespace) -> int:
    from omnisort_hw.errors import InputError

    if args.live is not None:
        return subprocess.call([*viewer_command(), live_url(args.live)])
    path: Path | None = args.file
    if path is None:
        raise InputError("review: give an .rrd file or --live HOST:PORT")
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
