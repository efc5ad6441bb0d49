"""`omnisort review FILE`: a run's `.rrd` file in the rerun viewer, its web viewer, or PNGs.

The native viewer needs a display: without one (no DISPLAY/WAYLAND_DISPLAY on Linux) review
refuses before anything starts or listens, and names the two ways that need none: `--web`
(rerun's web viewer and its gRPC server, both bound to 127.0.0.1 only) and `--png DIR` (the
recording's images with their logged points drawn, as PNG files). Nothing binds 0.0.0.0.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
from pathlib import Path

from omnisort_hw.cli.arg_types import Subcommands

LOOPBACK = "127.0.0.1"
NO_DISPLAY = (
    "review needs a display (no DISPLAY/WAYLAND_DISPLAY); use --web to serve rerun's web "
    "viewer on 127.0.0.1, or --png DIR to write the pictures"
)


def register(sub: Subcommands) -> None:
    p = sub.add_parser(
        "review",
        help="open a run's .rrd file in the rerun viewer (or --web, --png DIR, --list)",
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
    p.add_argument(
        "--web",
        action="store_true",
        help="no display needed: serve rerun's web viewer on 127.0.0.1 (open the printed URL "
        "in a browser; from another machine through an ssh tunnel) until interrupted",
    )
    p.add_argument(
        "--web-port",
        type=int,
        default=9090,
        help="with --web: the web viewer's HTTP port on 127.0.0.1 (0: any free one)",
    )
    p.add_argument(
        "--grpc-port",
        type=int,
        default=9876,
        help="with --web: the port of the gRPC server that feeds it the file (0: any free one)",
    )
    p.add_argument(
        "--png",
        type=Path,
        metavar="DIR",
        default=None,
        help="no display needed: write the recording's images (with their logged points and "
        "lines drawn, overlays as logged) as PNG files into DIR",
    )
    p.set_defaults(func=run)


def display_problem(env: dict[str, str] | None = None, platform: str = sys.platform) -> str | None:
    """Why the native viewer cannot open a window here (None: it can). Windows and macOS
    always have one; elsewhere an X11 or Wayland display must be named in the environment."""
    env = dict(os.environ) if env is None else env
    if platform.startswith(("win", "darwin")):
        return None
    if env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"):
        return None
    return NO_DISPLAY


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
        LOOPBACK,
        "--port",
        "0",
        "--save",
        str(out),
    ]


def web_command(source: str, web_port: int, grpc_port: int) -> list[str]:
    """rerun's web viewer for `source` (a file or a live URL) with its HTTP server and, for a
    file, the gRPC server it reads from, both on the loopback interface only."""
    return [
        *viewer_command(),
        source,
        "--web-viewer",
        "--bind",
        LOOPBACK,
        "--port",
        str(grpc_port),
        "--web-viewer-port",
        str(web_port),
    ]


def _port(value: int, flag: str) -> int:
    from omnisort_hw.errors import InputError

    if not 0 <= value < 65536:
        raise InputError(f"{flag} must be a port number 0-65535 (0: any free one), got {value}")
    return value


def _serve_web(source: str, args: argparse.Namespace, live: bool = False) -> int:
    """Run rerun's web viewer until interrupted, after saying where to point a browser (the
    browser fetches the viewer and then reads the data: both ports go through a tunnel)."""
    web = _port(args.web_port, "--web-port")
    grpc = _port(args.grpc_port, "--grpc-port")
    where = f"http://{LOOPBACK}:{web}" if web else "the address rerun prints below"
    print(f"review: rerun's web viewer on {where} (loopback only; Ctrl-C stops it)", flush=True)
    if web and (grpc or live):
        tunnel = f"ssh -L {web}:{LOOPBACK}:{web}"
        tunnel += "" if live else f" -L {grpc}:{LOOPBACK}:{grpc}"
        print(f"review: from another machine: {tunnel} THIS-HOST, then open {where}", flush=True)
    return subprocess.call(web_command(source, web, grpc))


def _write_pngs(path: Path, folder: Path) -> int:
    from omnisort_hw.pipeline.review import write_pictures

    written, skipped = write_pictures(path, folder)
    for png in written:
        print(png)
    for entity, why in sorted(skipped.items()):
        print(f"review: {entity} not written: {why}", file=sys.stderr)
    return 0


def run(args: argparse.Namespace) -> int:
    from omnisort_hw.errors import InputError, NoDisplayError

    if args.web and args.png is not None:
        raise InputError("review: --web serves a viewer, --png writes files: give one of them")
    if args.live is not None:
        if args.png is not None:
            raise InputError("review --png reads an .rrd file, not --live (save it first)")
        url = live_url(args.live)
        if args.web:
            return _serve_web(url, args, live=True)
        problem = display_problem()
        if problem:
            raise NoDisplayError(problem)
        return subprocess.call([*viewer_command(), url, "--bind", LOOPBACK])
    path: Path | None = args.file
    if path is None:
        raise InputError("review: give an .rrd file or --live HOST:PORT")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not an .rrd file")
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
    if args.png is not None:
        return _write_pngs(path, args.png)
    if args.web:
        return _serve_web(str(path), args)
    problem = display_problem()
    if problem:
        raise NoDisplayError(problem)
    # The viewer is interactive: it runs until the user closes it.
    return subprocess.call([*viewer_command(), str(path), "--bind", LOOPBACK])
