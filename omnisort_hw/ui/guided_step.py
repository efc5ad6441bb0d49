"""One guided step's end, for commissioning and recovery alike: what the verdict of the reply
lets the technician do next.

- PASS: the way on (Next, Accept) is shown.
- WARN: the plain way on stays hidden; only "Accept with warning" goes on, and it is logged
  (the interface's log, the journal under systemd) with the browser session and the verdict's
  figures, because a warning taken is a decision someone made.
- FAIL, or a refused or failed job: no way on; the note says why (each check with its figure
  and threshold) and what to do (the failing checks' advice), and the step is retaken.

The page's two guided flows build their steps from this one component, so a FAIL cannot be
accepted in one flow and not in the other.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from nicegui import ui

from omnisort_hw.pipeline.replies import Level
from omnisort_hw.pipeline.verdict import Verdict, verdict_lines, verdict_of
from omnisort_hw.service.states import JobRecord
from omnisort_hw.service.status_reading import job_text
from omnisort_hw.ui.job_runner import JobEnd, JobWatch
from omnisort_hw.ui.link import Call
from omnisort_hw.ui.widgets import tag
from omnisort_hw.wire_records import WireError

log = logging.getLogger(__name__)

LEVELS: tuple[Level, ...] = ("pass", "warn", "fail")
RETAKE = "the step cannot be accepted: fix the cause above and retake it"
WARNED = "accept with warning to go on, or fix the cause above and retake"


def verdict_text(verdict: Verdict | None) -> str:
    """A verdict in lines: PASS/WARN/FAIL first, then each check with its figure, its
    threshold and, when not a pass, what to do; "" for none."""
    return "" if verdict is None else "\n".join(line.strip() for line in verdict_lines(verdict))


def level_of(end: JobEnd) -> Level:
    """The step's level: its verdict's; fail for a job that failed or was refused; pass for a
    reply that carries no verdict."""
    if not end.ok or end.result is None:
        return "fail"
    try:
        verdict = verdict_of(end.result)
    except WireError:
        return "fail"  # a verdict it cannot read is never a way on
    return "pass" if verdict is None else verdict.level


class GuidedStep:
    """A step's note, its way on (`go`, shown on PASS) and its "Accept with warning" (shown on
    WARN, tagged `{go_tag}-warn`); `ended()` shows a job's end, `waiting()` a job started."""

    def __init__(
        self,
        name: str,
        note_tag: str,
        go_label: str | None,
        go_tag: str,
        go_on: Callable[[], None],
        session: str,
    ) -> None:
        """`name`: the step, for the log; `go_label`: the way on's label (None: a step with no
        way on of its own, such as a verification, whose acceptance is `accepted`); `session`:
        the browser session that accepts, for the log."""
        self.name, self.note_tag, self.go_label, self.go_tag = name, note_tag, go_label, go_tag
        self.go_on, self.session = go_on, session
        self.level: Level | None = None  # the last end's, None before one or while waiting
        self.accepted_warning = False

    @property
    def accepted(self) -> bool:
        """The step may be left: it passed, or its warning was accepted."""
        return self.level == "pass" or (self.level == "warn" and self.accepted_warning)

    def build_note(self) -> None:
        self.note = tag(ui.label(""), self.note_tag).classes("whitespace-pre-line")
        self.clock = tag(ui.label(""), f"{self.note_tag}-running").classes("text-sm")

    def build_buttons(self) -> None:
        """The way on and the acceptance of a warning, hidden until an end allows them."""
        self.go = (
            tag(ui.button(self.go_label, on_click=self.go_on), self.go_tag)
            if self.go_label is not None
            else None
        )
        self.warn = tag(
            ui.button("Accept with warning", on_click=self.accept_warning, color="amber-9"),
            f"{self.go_tag}-warn",
        )
        self._show_buttons()

    def _show_buttons(self) -> None:
        if self.go is not None:
            self.go.set_visibility(self.accepted)
        self.warn.set_visibility(self.level == "warn" and not self.accepted_warning)

    def reset(self, text: str = "") -> None:
        """Back to before any end (a step opened again, or a job started: `text` says so)."""
        self.level, self.accepted_warning = None, False
        self.note.text, self.clock.text = text, ""
        self._show_buttons()

    def waiting(self, doing: str) -> None:
        """A job started: what it is doing (`running` shows how long it has run)."""
        self.reset(doing)

    def running(self, job: JobRecord | None) -> None:
        """While the step's job runs, under its note: its running time and how long the last
        such job took on this cell (the service's `status` job)."""
        if self.level is None and job:
            self.clock.text = job_text(job, last_event=False)

    def start(self, watch: JobWatch, job: Call[object] | list[str], doing: str) -> bool:
        """Send the step's job through `watch`, or (`job` a list: the problems its command's
        schema found with the form, `Operators.checked`) nothing: the note says what is being
        done, or why nothing was sent."""
        if isinstance(job, list):
            self.refused("; ".join(job))
            return False
        if not watch.start(job):
            return False
        self.waiting(doing)
        return True

    def refused(self, why: str) -> None:
        """A request not sent (the schema or the page refused it): why, and no way on."""
        self.reset(f"not sent: {why}")

    def ended(self, end: JobEnd, lines: list[str] | None = None) -> Level:
        """Show how the job ended: its verdict (or its error) and the step's own `lines`, then
        what the level allows."""
        level = level_of(end)
        if not end.ok or end.result is None:
            text = [f"FAIL: {end.message}"]
        else:
            try:
                shown = verdict_text(verdict_of(end.result)) or f"{end.cmd} done"
            except WireError as exc:
                shown = f"FAIL: the reply's verdict cannot be read: {exc}"
            text = [shown, *(lines or [])]
        if level == "fail":
            text.append(RETAKE)
        elif level == "warn":
            text.append(WARNED)
        self.level, self.accepted_warning = level, False
        self.note.text, self.clock.text = "\n".join(line for line in text if line), ""
        self._show_buttons()
        return level

    def accept_warning(self) -> None:
        """The operator takes the warning: logged, then on as on a pass."""
        if self.level != "warn":
            return
        self.accepted_warning = True
        log.warning(
            "%s accepted with warning by the operator of browser session %s: %s",
            self.name,
            self.session,
            " | ".join(self.note.text.splitlines()[:-1]),
        )
        self.note.text += "\naccepted with warning (logged)"
        self._show_buttons()
        if self.go is None:
            return
        self.go_on()
