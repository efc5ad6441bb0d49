"""`omnisort ui --config cell.toml [--host H] [--port P]`: serve the operator interface."""

from __future__ import annotations

import argparse
import logging
import sys

from omnisort_hw.cli.arg_types import Subcommands


def register(sub: Subcommands) -> None:
    p = sub.add_parser(
        "ui",
        help="serve the operator interface (a web page; a client of the running service)",
        description=(
            "Serve the cell's operator interface over HTTP ([ui] host and port of the cell "
            "file; loopback unless set). It talks to the service of the same cell file "
            "([service] host and port) and holds no token: an operator signs in with the "
            "service token in the page."
        ),
    )
    p.add_argument("--config", required=True, help="cell configuration (TOML)")
    p.add_argument("--host", default=None, help="listen address (default: [ui] host)")
    p.add_argument("--port", type=int, default=None, help="HTTP port (default: [ui] port)")
    p.add_argument(
        "--service-port", type=int, default=None, help="service port (default: [service] port)"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from omnisort_hw.config.ui import load_ui_settings
    from omnisort_hw.ui.app import serve
    from omnisort_hw.ui.context import UiContext

    settings = load_ui_settings(args.config)
    logging.basicConfig(
        level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s"
    )
    host = settings.service_host
    port = args.service_port if args.service_port is not None else settings.service_port
    ctx = UiContext.for_service(settings.ui, host, port)
    listen_host = args.host or settings.ui.host
    listen_port = args.port if args.port is not None else settings.ui.port
    print(
        f"operator interface on http://{listen_host}:{listen_port} (service {host}:{port})",
        file=sys.stderr,
        flush=True,
    )
    serve(ctx, listen_host, listen_port)
    return 0
