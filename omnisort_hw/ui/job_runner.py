"""The job this interface started (one at a time, shared by every page): its request held on
a connection of its own until the reply, and how it ended. What a job is doing is read from the
service's status by every page, so a job started by another door shows the same way."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar, cast

from omnisort_hw.pipeline.replies import SortReply
from omnisort_hw.pipeline.verdict import verdict_lines, verdict_of
from omnisort_hw.ui.link import Call, ClientError, CommandError, ReplyError, ServiceLink

JOB_TIMEOUT_S = 3600.0
R = TypeVar("R")


@dataclass(frozen=True)
class JobEnd:
    """How a job this interface started ended, in words for the page."""

    cmd: str
    ok: bool
    message: str
    result: object | None  # the command's reply, read as its record
    ended: float  # time.monotonic()


def ended_text(cmd: str, result: object) -> str:
    """A job's reply in a line: done, a sort's totals, then its verdict."""
    parts = [f"{cmd} done"]
    if isinstance(result, SortReply):
        t = result.totals
        parts[0] += f": {t.sorted} sorted, {t.skipped} skipped, {t.failed} failed"
    verdict = verdict_of(result)
    if verdict is not None:
        parts += [line.strip() for line in verdict_lines(verdict)]
    return "; ".join(parts)


class JobRunner:
    """Starts a job on the service and keeps its end (`last`)."""

    def __init__(self, link: ServiceLink, timeout_s: float = JOB_TIMEOUT_S) -> None:
        self.link, self.timeout_s = link, timeout_s
        self._lock = threading.Lock()
        self._running: tuple[str, str] | None = None  # (command, browser session)
        self.last: JobEnd | None = None
        self.results: dict[str, object] = {}  # the last result of each command
        self.ended = 0  # how many jobs have ended (a page redraws what depends on them)

    @property
    def running(self) -> str | None:
        """The command of the job this interface is running, or None."""
        with self._lock:
            return self._running[0] if self._running else None

    def busy(self, browser: str) -> str | None:
        """Why `browser` cannot start a job now (one of this interface is still running, in
        that browser or another), or None."""
        with self._lock:
            return self._busy(browser)

    def _busy(self, browser: str) -> str | None:
        if self._running is None:
            return None
        cmd, by = self._running
        where = "in this browser" if by == browser else "from another browser"
        return f"{cmd} started {where} is still running"

    def start(self, job: Call[object], token: str | None, browser: str) -> None:
        """Send the job for the page of `browser` (its session) and return; its end lands in
        `last`. RuntimeError, with `busy()`'s reason, if one is still running."""
        with self._lock:
            if (why := self._busy(browser)) is not None:
                raise RuntimeError(why)
            self._running = (job.command, browser)
        threading.Thread(
            target=self._run, args=(job, token), name=f"ui-{job.command}", daemon=True
        ).start()

    def result(self, command: Callable[..., R]) -> R | None:
        """The last result of the job `command` (a `CellCommands` method), if one ended well:
        that method's typed reply."""
        with self._lock:
            return cast(R | None, self.results.get(command.__name__))

    def _run(self, job: Call[object], token: str | None) -> None:
        cmd = job.command
        try:
            result = self.link.call(job, token=token, timeout_s=self.timeout_s)
            end = JobEnd(cmd, True, ended_text(cmd, result), result, time.monotonic())
        except CommandError as exc:
            end = JobEnd(cmd, False, f"{cmd}: {exc.code}: {exc.message}", None, time.monotonic())
        except ReplyError as exc:
            end = JobEnd(cmd, False, str(exc), None, time.monotonic())
        except ClientError as exc:
            message = (
                f"{cmd}: the connection to the service was lost ({exc}); "
                "the service's state shows what became of the job"
            )
            end = JobEnd(cmd, False, message, None, time.monotonic())
        with self._lock:
            self.last = end
            if end.result is not None:
                self.results[cmd] = end.result
            self.ended += 1
            self._running = None


class JobWatch:
    """The job one panel started, followed until it ends: `start()` sends it through the page's
    one way to start a job and notes how many jobs had ended, so a job that ends at once is
    not missed; `ended()` gives its end once."""

    def __init__(self, jobs: JobRunner, start_job: Callable[[Call[object]], bool]) -> None:
        self.jobs, self.start_job = jobs, start_job
        self._waiting: tuple[str, int] | None = None  # (command, jobs ended when it started)

    @property
    def waiting(self) -> str | None:
        return self._waiting[0] if self._waiting else None

    def start(self, job: Call[object]) -> bool:
        ended = self.jobs.ended
        if not self.start_job(job):
            return False
        self._waiting = (job.command, ended)
        return True

    def ended(self) -> JobEnd | None:
        """The end of the job started here, once, when it has ended; else None."""
        if self._waiting is None:
            return None
        _, ended_before = self._waiting
        end = self.jobs.last
        if self.jobs.ended == ended_before or end is None:
            return None
        self._waiting = None
        return end
