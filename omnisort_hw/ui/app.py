"""`omnisort ui`: the interface's web server (NiceGUI, its assets inside the wheel: nothing is
downloaded at run time). `root()` is the page every browser gets; `serve()` runs it until
SIGTERM."""

from __future__ import annotations

import secrets
from collections.abc import Callable

from omnisort_hw.ui.context import UiContext

TITLE = "omnisort cell"


def root(ctx: UiContext) -> Callable[[], None]:
    """The page function NiceGUI calls for each browser."""

    def page() -> None:
        from omnisort_hw.ui.cell_page import cell_page

        cell_page(ctx)

    return page


def serve(ctx: UiContext, host: str, port: int) -> None:
    """Serve the interface on host:port until the process is told to stop."""
    from nicegui import app, ui

    app.on_shutdown(ctx.close)
    ui.run(
        root(ctx),
        host=host,
        port=port,
        title=TITLE,
        show=False,
        reload=False,
        # The session cookie is signed with a key of this process: a restart signs every
        # browser out, and no token ever outlives it.
        storage_secret=secrets.token_hex(32),
        show_welcome_message=False,
        favicon="🤖",
        uvicorn_logging_level="warning",
    )
