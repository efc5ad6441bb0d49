"""Run the service with the in-memory devices of `fakes.py` (for subprocess tests).

Usage: python -m tests.service.fake_service STATE_DIR LOG_DIR [--token T] [--move-seconds S]
       [--set KEY=JSON ...]   (any ServiceConfig field, e.g. --set write_timeout_s=2)
Prints `LISTENING HOST PORT` once the port is bound, then serves until SIGTERM / shutdown.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys
from pathlib import Path

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.service.server import Service
from omnisort_hw.service.systemd import Notifier
from tests.service.fakes import make_cell


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("state_dir", type=Path)
    ap.add_argument("log_dir", type=Path)
    ap.add_argument("--token", default=None)
    ap.add_argument("--move-seconds", type=float, default=30.0)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=JSON")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, stream=sys.stderr)
    cell, _, _ = make_cell(
        args.state_dir,
        args.log_dir,
        move_seconds=args.move_seconds,
        journal_path=args.state_dir / "journal.txt",
    )
    overrides = {k: json.loads(v) for k, v in (item.split("=", 1) for item in args.set)}
    service = Service(cell, ServiceConfig(port=0, token=args.token, **overrides), Notifier())

    async def run() -> int:
        host, port = await service.start()
        print(f"LISTENING {host} {port}", flush=True)
        return await service.run()

    return asyncio.run(run())


if __name__ == "__main__":
    sys.exit(main())
