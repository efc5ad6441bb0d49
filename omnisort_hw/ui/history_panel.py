"""Saving and going back: each calibration is saved by the step that made it, the version
before it kept by the store. This panel lists both files' versions (`history`: saved, checksum,
a summary, or why one does not verify) and goes back to a chosen one (`adopt` with its path,
after a confirmation: verified against the cell, saved as the current file, the current one
kept in its turn)."""

from __future__ import annotations

from nicegui import ui

from omnisort_hw.pipeline.replies import AdoptReply, VersionReply
from omnisort_hw.pipeline.requests import AdoptRequest, HistoryRequest
from omnisort_hw.ui.link import CellCommands, Send, StartJob, call_of
from omnisort_hw.ui.widgets import confirm, tag

KINDS = ("system", "camera")


def version_label(version: VersionReply) -> str:
    """A version in a line: when it was saved, what it holds, or why it does not verify."""
    if version.problem is not None:
        return f"DOES NOT VERIFY: {version.problem}"
    now = " (current)" if version.current else ""
    saved, checksum = version.saved or "", version.checksum or ""
    return f"{saved[:19]} {version.summary}, {checksum[:15]}{now}"


class HistoryPanel:
    """Both calibration files' versions, and going back to one."""

    def __init__(self, send: Send, start: StartJob) -> None:
        """`send`: the page's quick command; `start`: its panel's way to start a job whose end
        comes back to `ended()`."""
        self.send, self.start = send, start
        self.versions: dict[str, list[VersionReply]] = {}

    def build(self) -> None:
        ui.label(
            "Every calibration above was saved when it was made; the version before it is kept. "
            "Go back to a kept version if the new one proves worse."
        )
        self.lists: dict[str, ui.label] = {}
        self.pick: dict[str, ui.select] = {}
        for kind in KINDS:
            ui.label(f"{kind}.json").classes("font-bold")
            self.lists[kind] = tag(ui.label(""), f"history-{kind}").classes(
                "whitespace-pre-line text-sm"
            )
            with ui.row().classes("items-center"):
                self.pick[kind] = tag(
                    ui.select({}, label="kept version").classes("w-[36rem]"),
                    f"history-pick-{kind}",
                )
                tag(
                    ui.button("Go back to it", on_click=lambda k=kind: self.restore(k)),
                    f"history-restore-{kind}",
                )
        with ui.row().classes("items-center"):
            tag(ui.button("Reload", on_click=self.load).props("flat"), "history-reload")
        self.note = tag(ui.label(""), "history-note").classes("whitespace-pre-line")

    async def load(self) -> None:
        """Both files' versions, as the service lists them now."""
        for kind in KINDS:
            reply = await self.send(call_of(CellCommands.history, HistoryRequest(kind=kind)))
            if reply is None:
                return
            versions = reply.versions
            self.versions[kind] = versions
            self.lists[kind].text = "\n".join(version_label(v) for v in versions) or "none yet"
            kept = {
                v.path: version_label(v) for v in versions if not v.current and v.problem is None
            }
            self.pick[kind].set_options(kept, value=next(iter(kept), None))

    async def restore(self, kind: str) -> None:
        path = self.pick[kind].value
        if not path:
            self.note.text = f"{kind}: no kept version to go back to"
            return
        label = version_label(next(v for v in self.versions[kind] if v.path == path))
        if not await confirm(
            f"Go back to the {kind} calibration {label}? The current one is kept in the history."
        ):
            self.note.text = "nothing was sent"
            return
        if self.start(call_of(CellCommands.adopt, AdoptRequest(**{kind: path}))):
            self.note.text = f"going back to {path}..."

    async def ended(self, ok: bool, message: str, result: AdoptReply | None) -> None:
        """The end of a restore this panel started: what is current now."""
        if not ok or result is None:
            self.note.text = f"FAIL: {message}"
        else:
            self.note.text = "\n".join(
                f"{kind}.json is now {a.source} (checksum {a.checksum[:15]})"
                for kind, a in result.adopted.items()
            )
        await self.load()
