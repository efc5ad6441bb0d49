"""`omnisort serve --config cell.toml [--host H] [--port P]`: run the cell service."""

from __future__ import annotations

import argparse
import logging
import os
import sys

from omnisort_hw.cli.arg_types import Subcommands


def register(sub: Subcommands) -> None:
    p = sub.add_parser(
        "serve",
        help="run the cell service (TCP line-delimited JSON; systemd Type=notify)",
        description=(
            "Open the devices of the cell configuration and serve the control protocol until "
            "SIGTERM. Binds 127.0.0.1 unless configured or told otherwise; off loopback a "
            "token ([service] token or token_file) is required."
        ),
    )
    p.add_argument("--config", required=True, help="cell configuration (TOML)")
    p.add_argument("--host", default=None, help="listen address (default: [service] host)")
    p.add_argument("--port", type=int, default=None, help="TCP port (default: [service] port)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.service.entry import serve

    settings = load_cell_config(args.config)
    logging.basicConfig(
        level=settings.logging.level,
        stream=sys.stderr,
        format="%(levelname)s %(name)s: %(message)s",
    )
    code = serve(settings, host=args.host, port=args.port)
    if code == 0:
        # A clean stop: devices closed, logs flushed. A device library may still own a native
        # thread (an OpenCV stream read that waits for the next frame); the interpreter's
        # finalization would unwind it through C++ and abort the process (SIGABRT, "exception
        # not rethrown"), so a clean stop would look like a crash to systemd. Leave without it.
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    return code
