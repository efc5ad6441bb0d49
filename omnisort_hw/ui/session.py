"""One browser's session, which the page and its panels share instead of passing callables:
who it is (the browser's id), whether it acts as the operator (its token), the message it was
last told (kept until it is stale), its one way to send a quick command and to start a job, and
the page's one timer (`tick`), which refreshes each panel that asked at that panel's own
period. The page binds its message label to `message`."""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from nicegui import background_tasks, run, ui

from omnisort_hw.pipeline.requests import LaserRequest
from omnisort_hw.service.client import ClientError
from omnisort_hw.service.commands import Call, CellCommands, CommandError, call_of
from omnisort_hw.ui.context import UiContext

R = TypeVar("R")
MIN_PERIOD_S = 0.05
"""The shortest period a refresh may ask (the cell file's `[ui]` periods keep to it too)."""


@dataclass
class _Refresh:
    """A panel's refresh and its period; `due`: the monotonic time it runs next; `running`: a
    coroutine of it not yet done (a slow answer), so it is not started again meanwhile."""

    refresh: Callable[[], object]
    period_s: float
    due: float = 0.0
    running: bool = False

    def finished(self, _task: object) -> None:
        self.running = False


class BrowserSession:
    """One browser's page state and doors to the service."""

    def __init__(self, ctx: UiContext, browser: str) -> None:
        self.ctx, self.browser = ctx, browser
        self.message = ""  # what this browser was last told (the label under the header)
        self._stale: Callable[[], bool] | None = None
        self._refreshes: list[_Refresh] = []
        self._ended_seen = ctx.jobs.ended  # the interface's jobs ended when last ticked

    # -- who ------------------------------------------------------------------------------

    @property
    def operator(self) -> bool:
        """True when this browser is signed in as the operator."""
        return self.ctx.operators.signed_in(self.browser)

    def token(self) -> str | None:
        """This session's operator token; None, with why said, when not signed in."""
        token = self.ctx.operators.token(self.browser)
        if token is None:
            self.say("sign in as operator first: nothing was sent", "negative")
        return token

    # -- saying ---------------------------------------------------------------------------

    def say(self, text: str, kind: str = "info", until: Callable[[], bool] | None = None) -> None:
        """A message under the header (and a notification); `until`: once it holds, the
        message is stale and `expire` takes it away (a job that has ended, a service back)."""
        self.message, self._stale = text, until
        ui.notify(text, type=kind)  # type: ignore[arg-type]

    def expire(self) -> None:
        """The message taken away once its `until` holds."""
        if self._stale is not None and self._stale():
            self.message, self._stale = "", None

    def unreachable(self, cmd: str) -> None:
        """Not sent for want of the service: said until the service answers again."""
        self.say(
            f"{cmd}: not sent, the service is unreachable",
            "negative",
            lambda: self.ctx.link.snapshot.reachable,
        )

    # -- doing ----------------------------------------------------------------------------

    async def send(self, command: Call[R], token: str | None = None) -> R | None:
        """One quick command; its reply, or None with the refusal said."""
        if not self.ctx.link.snapshot.reachable:
            self.unreachable(command.command)
            return None
        try:
            return await run.io_bound(self.ctx.link.call, command, token)
        except CommandError as exc:
            self.say(f"{command.command}: {exc.code}: {exc.message}", "negative")
        except ClientError as exc:
            self.say(f"{command.command}: the service cannot be reached: {exc}", "negative")
        return None

    async def operator_send(self, command: Call[R]) -> R | None:
        """One quick command with this session's token; None, with why, when not sent."""
        token = self.token()
        if token is None:
            return None
        return await self.send(command, token)

    def start_job(self, job: Call[object]) -> bool:
        """Start a job on the service for this operator; False, with the reason said, when it
        was not sent. Motion is confirmed before this (the sort's Start), never here."""
        token = self.token()
        if token is None:
            return False
        if not self.ctx.link.snapshot.reachable:
            self.unreachable(job.command)
            return False
        try:
            self.ctx.jobs.start(job, token, self.browser)
        except RuntimeError as exc:
            self.say(f"{job.command}: not sent: {exc}", "negative")
            return False
        ended = self.ctx.jobs.ended
        self.say(f"{job.command} started", until=lambda: self.ctx.jobs.ended > ended)
        return True

    async def laser(self, on: bool) -> None:
        """The laser switched by the operator."""
        job = call_of(CellCommands.laser, LaserRequest(on=on))
        if await self.operator_send(job) is not None:
            self.say(f"laser {'on' if on else 'off'}")

    # -- the page's one timer --------------------------------------------------------------

    def every(self, period_s: float, refresh: Callable[[], object]) -> None:
        """`refresh` (a panel's; it may be a coroutine) run by the page's timer every
        `period_s`."""
        self._refreshes.append(_Refresh(refresh, max(period_s, MIN_PERIOD_S)))

    @property
    def tick_s(self) -> float:
        """The page's timer's period: the shortest a refresh asked for."""
        return min((r.period_s for r in self._refreshes), default=0.5)

    def tick(self) -> None:
        """Each refresh that is due, in the order they asked; every one, after a job of this
        interface has ended, so a step waiting for its job shows the end within a tick, not
        within its own period. A coroutine runs as a task of its own in the page's context, so
        a slow answer holds back no other refresh."""
        ended = self.ctx.jobs.ended
        if ended != self._ended_seen:
            self._ended_seen = ended
            for r in self._refreshes:
                r.due = 0.0
        for r in self._refreshes:
            now = time.monotonic()
            if now < r.due or r.running:
                continue
            r.due = now + r.period_s
            done = r.refresh()
            if inspect.isawaitable(done):
                r.running = True
                task = background_tasks.create(done, name="page refresh", context=ui.context.slot)
                task.add_done_callback(r.finished)
