"""Pictures the service wrote (a calibration's residual picture, the intrinsics' report and
uncertainty map), fetched with `picture` for a page: the service sends only PNGs of its store's
folder, scaled and JPEG-encoded."""

from __future__ import annotations

from nicegui import run

from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.link import ClientError, CommandError

__all__ = ["ClientError", "CommandError", "fetch_picture"]


async def fetch_picture(ctx: UiContext, token: str, path: str, width: int = 960) -> str | None:
    """The picture at `path` as a data URL (None when the interface is shutting down);
    CommandError or ClientError when the service does not send it."""
    sent = await run.io_bound(ctx.link.execute, "picture", {"path": path, "width": width}, token)
    if sent is None:
        return None
    return f"data:image/jpeg;base64,{sent['base64']}"
