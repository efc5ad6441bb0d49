"""The job this interface started (one at a time, shared by every page): its request held on
a connection of its own until the reply, and how it ended. What a job is doing is read from the
service's status by every page, so a job started by another door shows the same way."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from omnisort_hw.pipeline.verdict import verdict_lines
from omnisort_hw.ui.link import ClientError, CommandError, ServiceLink

JOB_TIMEOUT_S = 3600.0


@dataclass(frozen=True)
class JobEnd:
    """How a job this interface started ended, in words for the page."""

    cmd: str
    ok: bool
    message: str
    result: Mapping[str, Any] | None
    ended: float  # time.monotonic()


def ended_text(cmd: str, result: Mapping[str, Any]) -> str:
    """A job's reply in a line: done, a sort's totals, then its verdict."""
    parts = [f"{cmd} done"]
    totals = result.get("totals")
    if isinstance(totals, Mapping):
        counts = ("sorted", "skipped", "failed")
        parts[0] += ": " + ", ".join(f"{totals.get(k, 0)} {k}" for k in counts)
    if isinstance(result.get("verdict"), Mapping):
        parts += [line.strip() for line in verdict_lines(result["verdict"])]
    return "; ".join(parts)


class JobRunner:
    """Starts a job on the service and keeps its end (`last`)."""

    def __init__(self, link: ServiceLink, timeout_s: float = JOB_TIMEOUT_S) -> None:
        self.link, self.timeout_s = link, timeout_s
        self._lock = threading.Lock()
        self._running: str | None = None
        self.last: JobEnd | None = None
        self.results: dict[str, Mapping[str, Any]] = {}  # the last result of each command
        self.ended = 0  # how many jobs have ended (a page redraws what depends on them)

    @property
    def running(self) -> str | None:
        """The command of the job this interface is waiting on, or None."""
        with self._lock:
            return self._running

    def start(self, cmd: str, args: dict[str, Any], token: str | None) -> None:
        """Send the job and return; its end lands in `last`. RuntimeError if one is waiting."""
        with self._lock:
            if self._running is not None:
                raise RuntimeError(f"{self._running} started here is still running")
            self._running = cmd
        threading.Thread(
            target=self._run, args=(cmd, args, token), name=f"ui-{cmd}", daemon=True
        ).start()

    def _run(self, cmd: str, args: dict[str, Any], token: str | None) -> None:
        try:
            result = self.link.execute(cmd, args, token=token, timeout_s=self.timeout_s)
            end = JobEnd(cmd, True, ended_text(cmd, result), result, time.monotonic())
        except CommandError as exc:
            end = JobEnd(cmd, False, f"{cmd}: {exc.code}: {exc.message}", None, time.monotonic())
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

    def __init__(self, jobs: JobRunner, start_job: Callable[[str, dict[str, Any]], bool]) -> None:
        self.jobs, self.start_job = jobs, start_job
        self._waiting: tuple[str, int] | None = None  # (command, jobs ended when it started)

    @property
    def waiting(self) -> str | None:
        return self._waiting[0] if self._waiting else None

    def start(self, cmd: str, args: dict[str, Any]) -> bool:
        ended = self.jobs.ended
        if not self.start_job(cmd, args):
            return False
        self._waiting = (cmd, ended)
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
