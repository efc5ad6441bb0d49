"""Run one virtual cell in this process until SIGTERM/SIGINT; prints `ready HOST` once every
port accepts (what `omnisort sim virtual-cell` runs; `launcher.VirtualCellProcess` starts that
command in a child process). Its arguments are the CLI's (`cli/virtual_cell_args.py`)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading


def serve(args: argparse.Namespace) -> int:
    """Start the cell, print `ready HOST`, wait for SIGTERM or SIGINT, close in order."""
    from sim_backend.virtual_cell.cell import VirtualCell

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    group, _, pin = args.gripper_output.partition(":")
    if group not in ("tool", "standard", "configurable") or not pin.isdigit():
        print(
            f"--gripper-output must look like tool:0, got {args.gripper_output!r}", file=sys.stderr
        )
        return 2
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    try:
        cell = VirtualCell(
            args.scene,
            args.host,
            width=args.width,
            seed=args.seed,
            fps=args.fps,
            unlock_delay_s=args.unlock_delay,
            gripper_output=(group, int(pin)),
            degraded=args.degraded,
            effects=args.effects,
        )
    except OSError as exc:
        print(f"cannot serve on {args.host}: {exc} (another virtual cell there?)", file=sys.stderr)
        return 1
    try:
        cell.start()
        print(f"ready {args.host}", flush=True)
        while not stop.wait(0.5):
            pass
    finally:
        cell.close()
    return 0
