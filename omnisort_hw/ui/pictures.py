"""Pictures the service wrote (a calibration's residual picture, the intrinsics' report and
uncertainty map), fetched with `picture` for a page: the service sends only PNGs of its store's
folder, scaled and JPEG-encoded."""

from __future__ import annotations

from nicegui import run, ui

from omnisort_hw.pipeline.requests import PictureRequest
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.link import CellCommands, ClientError, CommandError, call_of

__all__ = ["ClientError", "CommandError", "fetch_picture", "show_picture"]


async def fetch_picture(ctx: UiContext, token: str, path: str, width: int = 960) -> str | None:
    """The picture at `path` as a data URL (None when the interface is shutting down);
    CommandError or ClientError when the service does not send it."""
    job = call_of(CellCommands.picture, PictureRequest(path=path, width=width))
    sent = await run.io_bound(ctx.link.call, job, token)
    if sent is None:
        return None
    return sent.data_url


async def show_picture(
    ctx: UiContext, token: str | None, path: object, image: ui.image, note: ui.label
) -> None:
    """The picture at `path` (a reply's) in the `image` element; none without a path or a
    token; why not appended to the `note` label when the service does not send it."""
    if not path or token is None:
        image.set_source("")
        return
    try:
        source = await fetch_picture(ctx, token, str(path))
    except (CommandError, ClientError) as exc:
        note.text += f"\nthe picture {path} could not be shown: {exc}"
        return
    if source is not None:
        image.set_source(source)
