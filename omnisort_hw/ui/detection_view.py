"""A live picture with a calibration pattern's detection drawn on it: while it is shown, the
service's `detect` is asked every `view_period_s` (one request at a time, with this session's
token) and its picture, layers and summary replace the last. Used where a person places a
target or a board: the recovery after a bump and the commissioning."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from nicegui import run, ui

from omnisort_hw.pipeline.replies import DetectReply
from omnisort_hw.pipeline.requests import DetectRequest
from omnisort_hw.ui.link import CellCommands, ClientError, CommandError, call_of
from omnisort_hw.ui.overlay_svg import Overlay, detection_overlay
from omnisort_hw.ui.session import BrowserSession
from omnisort_hw.ui.widgets import tag


class LiveDetection:
    """`build()` in a container; `active` turns the asking on and off; `found` is the last
    reply's verdict (None before the first)."""

    def __init__(
        self,
        session: BrowserSession,
        request: Callable[[], DetectRequest],
        name: str,
        extra: Callable[[float, float], Overlay | None] | None = None,
    ) -> None:
        """`session`: the browser's (its token; its timer asks again); `request`: the `detect`
        request at each ask (the pattern as the page sets it now); `name`: the tests' name of
        its elements (`NAME-image`, `NAME-summary`); `extra`: a further overlay drawn under the
        detection, given the picture's scale and unit."""
        self.session, self.ctx = session, session.ctx
        self.token, self.request, self.name = session.token, request, name
        self.extra = extra
        self.active = False
        self.found: bool | None = None
        self.last: DetectReply | None = None
        self._busy = False

    def build(self) -> None:
        self.summary = tag(ui.label(""), f"{self.name}-summary").classes("text-sm")
        self.image = tag(
            ui.interactive_image().classes("w-full max-w-[960px]"), f"{self.name}-image"
        )
        self.session.every(self.ctx.config.view_period_s, self.tick)

    async def tick(self) -> None:
        """Ask once, unless not shown, still waiting for the last answer, signed out, or the
        cell busy with a job."""
        if not self.active or self._busy or self.cell_busy():
            return
        token = self.token()
        if token is None:
            self.summary.text = "sign in as operator to see the detection"
            return
        request = replace(self.request(), width=self.ctx.config.view_width_px)
        self._busy = True
        try:
            job = call_of(CellCommands.detect, request)
            reply = await run.io_bound(self.ctx.link.call, job, token)
        except CommandError as exc:
            self.found, self.summary.text = False, f"no detection: {exc.code}: {exc.message}"
            return
        except (ClientError, OSError) as exc:
            self.found = False
            self.summary.text = f"no detection: the service cannot be reached: {exc}"
            return
        finally:
            self._busy = False
        if reply is None or not self.active:  # shutting down, or hidden meanwhile
            return
        self.show(reply)

    def cell_busy(self) -> bool:
        """A job is running: one this interface started (known at once) or one the service's
        last status shows (from another door). A detection then waits: the job's frames are
        its own (the laser switched, the floor checked), and on the cell's 2-core PC each
        detection took the job's cores, so the page's calibrations ran longer than `ctl`'s."""
        return self.ctx.jobs.running is not None or self.ctx.link.running_job() is not None

    def show(self, reply: DetectReply) -> None:
        picture = reply.picture
        if picture is None:  # the service sends one with every detection
            self.found, self.summary.text = reply.found, reply.summary
            return
        scale, unit = picture.scale, picture.width / 960.0
        overlays = [self.extra(scale, unit) if self.extra else None]
        overlays.append(detection_overlay(reply, scale, unit))
        shown = [o for o in overlays if o is not None]
        self.last, self.found = reply, reply.found
        self.image.set_source(picture.data_url)
        self.image.content = "".join(o.svg for o in shown)
        self.summary.text = "; ".join(o.legend for o in reversed(shown))
