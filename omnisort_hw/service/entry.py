"""The service process: every check that needs no device, then open the cell, listen, notify
systemd and run until SIGTERM (`omnisort serve`)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import faulthandler
import logging
import signal
import sys

from omnisort_hw import fileio
from omnisort_hw.cell.cell import Cell
from omnisort_hw.cell.lock import InstanceLock
from omnisort_hw.config.cell import CellConfig
from omnisort_hw.service.listener import preflight
from omnisort_hw.service.live_view import start_live_view
from omnisort_hw.service.plc_face import start_plc_face
from omnisort_hw.service.server import SWITCH_INTERVAL_S, Service
from omnisort_hw.service.systemd import Notifier

log = logging.getLogger("omnisort.service")


def check_directories(settings: CellConfig) -> None:
    """The state and log directories must be writable before anything else happens."""
    fileio.check_writable(settings.storage.state_dir, "[storage] state_dir")
    if settings.logging.rerun:
        fileio.check_writable(settings.logging.log_dir, "[logging] log_dir")


def serve(
    settings: CellConfig,
    host: str | None = None,
    port: int | None = None,
    cell: Cell | None = None,
) -> int:
    """`omnisort serve`: open the cell, listen, notify systemd, run until SIGTERM; exit code."""
    cfg = dataclasses.replace(
        settings.service,
        host=host if host is not None else settings.service.host,
        port=port if port is not None else settings.service.port,
    )
    # `kill -USR1 PID` prints every thread's stack to stderr (journald): for a stuck device.
    with contextlib.suppress(AttributeError, ValueError, OSError):
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    # A shorter GIL switch interval keeps the event loop answering while a job computes.
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    notifier = Notifier()
    check_directories(settings)
    with InstanceLock(settings.storage.state_dir):
        # Every check that needs no device comes first: a refused start opens nothing.
        preflight(settings, cfg)
        notifier.status("opening devices")
        with contextlib.ExitStack() as opened:
            opened.callback(notifier.close)
            cell = cell or Cell.from_settings(settings, devices_in_child=True)  # no pybullet
            closing = opened.enter_context(contextlib.ExitStack())
            closing.callback(cell.close)  # until the service owns the cell (it closes it)
            cell.connect()
            service = Service(cell, cfg, notifier)
            plc = start_plc_face(service, settings.plc)
            if plc is not None:
                opened.callback(plc.close)
            live = start_live_view(settings.logging.live, cell.runlog)
            if live is not None:
                opened.callback(live.close)
            closing.pop_all()
            code = asyncio.run(service.run())
    if service.exit_problems:
        log.warning("stopped with problems: %s", "; ".join(service.exit_problems))
    return code
