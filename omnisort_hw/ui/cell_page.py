"""The cell page: the state, the devices and the calibration, the running job and its per-pick
log, Stop and E-stop (always shown, open to everyone, as in the protocol), the laser, and the
sort form built from the command's schema. Everything shown is read from the service's status
(`ServiceLink.snapshot`); everything done is a command of the protocol.

Operator actions need the session to be signed in (`Operators`); anything that can move the
arm asks for an explicit confirmation first; every argument is checked against the command's
schema before anything is sent, and a refusal is shown as the service's typed message.
"""

from __future__ import annotations

from dataclasses import asdict
from datetime import UTC, datetime
from typing import Any

from nicegui import app, run, ui

from omnisort_hw.pipeline.requests import MapRequest
from omnisort_hw.service.status_reading import (
    PickHistory,
    drift_alarm,
    job_text,
    motion_offered,
    picks_per_minute,
    sort_progress,
    status_rows,
)
from omnisort_hw.ui.cell_3d import Cell3D
from omnisort_hw.ui.commissioning import CommissioningPanel
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.link import CellCommands, call_of
from omnisort_hw.ui.operators import SignInError
from omnisort_hw.ui.overlay_svg import cubes_overlay, map_overlay
from omnisort_hw.ui.recovery import RecoveryPanel
from omnisort_hw.ui.schema_form import form_fields
from omnisort_hw.ui.schema_widgets import SchemaForm
from omnisort_hw.ui.session import BrowserSession
from omnisort_hw.ui.sim_panel import SimulatorPanel
from omnisort_hw.ui.widgets import confirm, tag

STATE_COLORS = {
    "idle": "positive",
    "sorting": "primary",
    "mapping": "primary",
    "calibrating": "primary",
    "moving": "primary",
    "stopped": "warning",
    "fault": "negative",
}
PICK_COLUMNS = [
    {"name": k, "label": label, "field": k, "align": "left"}
    for k, label in (
        ("n", "#"),
        ("sort", "sort"),
        ("cube", "cube"),
        ("color", "colour"),
        ("bin", "bin"),
        ("outcome", "outcome"),
        ("reason", "reason"),
        ("at", "time"),
    )
]


LIVE_TABS = ("Cell", "Simulator")
"""The tabs that show the live picture: the others show their own (a step's detection, the
3D scene), so the interface asks the service for the live picture only while one of these
is shown in some browser."""


class CellPage:
    """One browser's cell page; `refresh()` (a timer) redraws it from the last snapshot."""

    def __init__(self, ctx: UiContext, browser: str) -> None:
        self.ctx, self.browser = ctx, browser
        self.sort_fields: SchemaForm | None = None  # drawn once signed in
        self._picks_shown: list[dict[str, Any]] = []
        self.pick_history = PickHistory()  # this page's sorts, numbered across them
        self.simulator: SimulatorPanel | None = None
        self.session = BrowserSession(ctx, browser)
        self.start_button: Any = None
        self._watching = False  # this page counts among the live feed's watchers

    # -- building -------------------------------------------------------------------------

    def build(self) -> None:
        with ui.header().classes("items-center gap-4 bg-slate-800"):
            ui.label("omnisort cell").classes("text-lg font-bold")
            self.state = tag(ui.badge("…"), "state").classes("text-base")
            self.link_label = tag(ui.label(""), "link")
            ui.space()
            tag(ui.button("Stop", on_click=self.stop, color="orange"), "stop")
            tag(ui.button("E-stop", on_click=self.estop, color="red"), "estop")
        self.down = tag(ui.label(""), "unreachable").classes(
            "w-full p-3 bg-red-100 text-red-900 font-bold"
        )
        with ui.row().classes("w-full items-center p-3 bg-amber-100") as self.drift_row:
            self.drift = tag(ui.label(""), "drift").classes("text-amber-900 font-bold")
            self.recover_button = tag(
                ui.button("Recover", on_click=self.start_recovery, color="amber-9"), "recover"
            )
        self.message = tag(ui.label("").bind_text_from(self.session, "message"), "message")
        self.message.classes("w-full text-base")
        with ui.row().classes("w-full items-start gap-4 no-wrap"):
            with ui.column().classes("gap-4"):
                self._build_operator()
                self._build_status()
            with ui.column().classes("gap-4 grow min-w-0"):
                self.recovery = RecoveryPanel(self.session)
                if self.ctx.sim is not None:  # built in its tab, offered to the commissioning
                    self.simulator = SimulatorPanel(self.session, self.ctx.sim)
                self.recovery.build()
                self._build_job()
                with ui.tabs().classes("w-full") as tabs:
                    tag(ui.tab("Cell"), "tab-cell")
                    tag(ui.tab("Commission"), "tab-commission")
                    tag(ui.tab("3D"), "tab-3d")
                    if self.ctx.sim is not None:
                        tag(ui.tab("Simulator"), "tab-simulator")
                with ui.tab_panels(tabs, value="Cell").classes("w-full") as panels:
                    with ui.tab_panel("Cell").classes("gap-4 p-0"):
                        self._build_view()
                        self._build_sort()
                    with ui.tab_panel("Commission").classes("p-0"):
                        self.commissioning = CommissioningPanel(
                            self.session,
                            self.simulator.next_board if self.simulator is not None else None,
                        )
                        self.commissioning.build()
                    with ui.tab_panel("3D").classes("p-0"):
                        self.cell_3d = Cell3D(self.ctx)
                        self.cell_3d.build()
                    if self.simulator is not None:
                        with ui.tab_panel("Simulator").classes("p-0"):
                            self.simulator.build()
                panels.on_value_change(self._tab_shown)

    def _tab_shown(self, event: Any) -> None:
        self.watch_feed(event.value in LIVE_TABS)
        self.commissioning.show(event.value == "Commission")
        self.cell_3d.show(event.value == "3D")
        if self.simulator is not None:
            self.simulator.show(event.value == "Simulator")

    def _build_operator(self) -> None:
        with ui.card().classes("w-[30rem]"):
            ui.label("Operator").classes("text-lg")
            if not self.ctx.operators.allowed:
                tag(ui.label("View-only screen ([ui] allow_operator = false)"), "view-only")
                return
            self.signed_label = tag(ui.label(""), "signed")
            with ui.row().classes("items-center") as self.sign_in_row:
                self.token_input = tag(
                    ui.input("service token", password=True).classes("w-52"), "token"
                )
                tag(ui.button("Sign in", on_click=self.sign_in), "sign-in")
            self.sign_out_button = tag(
                ui.button("Sign out", on_click=self.sign_out).props("flat"), "sign-out"
            )
            with ui.row().classes("items-center") as self.operator_row:
                ui.label("Laser")
                tag(
                    ui.button("On", on_click=lambda: self.session.laser(True)).props("flat"),
                    "laser-on",
                )
                tag(
                    ui.button("Off", on_click=lambda: self.session.laser(False)).props("flat"),
                    "laser-off",
                )
                tag(ui.button("Reset", on_click=self.reset).props("flat"), "reset")
                tag(
                    ui.button("Acknowledge drift", on_click=self.acknowledge).props("flat"),
                    "acknowledge",
                )

    def _build_status(self) -> None:
        with ui.card().classes("w-[30rem]"):
            ui.label("Cell").classes("text-lg")
            self.rows = tag(
                ui.table(
                    columns=[
                        {"name": "k", "label": "", "field": "k", "align": "left"},
                        {"name": "v", "label": "", "field": "v", "align": "left"},
                    ],
                    rows=[],
                    row_key="i",
                ).props("dense flat hide-header wrap-cells"),
                "status-rows",
            ).classes("w-full")

    def _build_job(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Job").classes("text-lg")
            self.job_label = tag(ui.label("none"), "job")
            self.progress = tag(ui.linear_progress(0.0, show_value=False), "progress")
            self.job_end = tag(ui.label(""), "job-end")

    def _build_view(self) -> None:
        with ui.card().classes("w-full"):
            with ui.row().classes("items-center gap-4"):
                ui.label("Live view").classes("text-lg")
                self.view_note = tag(ui.label(""), "view-note")
            self.view = tag(ui.interactive_image().classes("w-full max-w-[960px]"), "live-view")
            self.view_legend = tag(ui.label(""), "view-legend").classes("text-sm")
            with ui.row().classes("items-center") as self.view_ops:
                tag(ui.button("Map the laser line", on_click=self.map_line), "map")
                tag(ui.button("Locate the cubes", on_click=self.locate), "locate")
        self._view_shown: tuple[int, int] = (-1, -1)

    def _build_sort(self) -> None:
        with ui.card().classes("w-full"):
            with ui.row().classes("items-center gap-4"):
                ui.label("Sort").classes("text-lg")
                self.rate = tag(ui.label(""), "picks-per-min")
            self.sort_form = ui.row().classes("items-center gap-4")
            self.sort_problems = tag(ui.label(""), "sort-problems").classes("text-red-700")
            self.picks = tag(
                ui.table(columns=PICK_COLUMNS, rows=[], row_key="n").props("dense flat"),
                "pick-log",
            ).classes("w-full")

    def _fill_sort_form(self) -> None:
        """The sort form from the command's schema, once the session is signed in."""
        schema = self.ctx.operators.schema(CellCommands.sort)
        if schema is None or self.sort_fields is not None:
            return
        with self.sort_form:
            self.sort_fields = SchemaForm(form_fields(schema), "sort")
            self.start_button = tag(ui.button("Start sort", on_click=self.start_sort), "start-sort")

    # -- reading --------------------------------------------------------------------------

    def refresh(self) -> None:
        snap = self.ctx.link.snapshot
        self.session.expire()
        operator = self.session.operator
        if self.ctx.operators.allowed:
            self.sign_in_row.set_visibility(not operator)
            self.sign_out_button.set_visibility(operator)
            self.operator_row.set_visibility(operator)
            self.signed_label.text = (
                "Signed in as operator" if operator else "Read-only: sign in for operator actions"
            )
        if operator:
            self._fill_sort_form()
        self.sort_form.set_visibility(operator)
        end = self.ctx.jobs.last
        self.job_end.text = end.message if end is not None else ""
        self.recovery.show(operator and self.recovery.active)
        if snap.status is None:
            self.drift_row.set_visibility(False)
            self.state.text, self.state.props["color"] = "unreachable", "grey"
            self.down.text = f"{snap.problem}; trying again every {self.ctx.link.period_s:g} s"
            self.down.set_visibility(True)
            self.link_label.text = "service: unreachable"
            self._show_start(False)
            if self.rows.rows:  # the last status is not the cell's now
                self.rows.rows = []
                self.rows.update()
            return
        status: dict[str, Any] = dict(snap.status)
        self.down.set_visibility(False)
        self.link_label.text = f"service: {self.ctx.link.address}"
        state = str(status.get("state", "?"))
        self.state.text = state
        self.state.props["color"] = STATE_COLORS.get(state, "grey")
        self.state.update()
        alarm = drift_alarm(status)
        self.drift.text = f"Calibration drift: {alarm}" if alarm else ""
        self.drift_row.set_visibility(alarm is not None)
        self.recover_button.set_visibility(operator and not self.recovery.active)
        rows = [{"i": i, "k": k, "v": v} for i, (k, v) in enumerate(status_rows(status))]
        if rows != self.rows.rows:
            self.rows.rows = rows
            self.rows.update()
        self._show_job(status)
        self._show_start(motion_offered(status) and state in ("idle", "stopped"))

    def _show_start(self, allowed: bool) -> None:
        """Start sort is enabled only when the service would take a sort now."""
        button = self.start_button  # built with the form, at the sign-in
        if button is not None and button.enabled != allowed:
            button.set_enabled(allowed)

    def _show_job(self, status: dict[str, Any]) -> None:
        job = status.get("job")
        self.job_label.text = job_text(job, last_event=False)
        done_total = sort_progress(status)
        self.progress.value = (
            done_total[0] / done_total[1] if done_total and done_total[1] else (1.0 if job else 0)
        )
        self.progress.props["indeterminate"] = bool(job) and not done_total
        self.progress.update()
        picks = [
            {"n": n, "sort": k, **asdict(row), "at": row.at[11:19]}
            for n, k, row in self.pick_history.update(status)
        ]
        if picks != self._picks_shown:
            self._picks_shown = picks
            self.picks.rows = picks
            self.picks.update()
        rate = picks_per_minute(status, datetime.now(UTC))
        self.rate.text = f"{rate:.1f} picks/min" if rate is not None else ""

    def watch_feed(self, shown: bool) -> None:
        """This page shows the live picture (`shown`) or not: counted among the feed's
        watchers once while it does. Unwatched, the picture a second nobody sees is neither
        asked of the service nor sent to the browser: with the Commission tab shown, the views
        step took 1.7 s less."""
        if shown != self._watching:
            (self.ctx.feed.watch if shown else self.ctx.feed.unwatch)()
            self._watching = shown

    def refresh_view(self) -> None:
        """The newest live picture and the overlays of the last map and location."""
        feed = self.ctx.feed
        pic = feed.picture
        fps = feed.fps
        rate = f", {fps:.1f} pictures/s" if fps is not None else ""
        self.view_note.text = feed.problem or (
            f"picture {pic.sequence} at {pic.wall_time[11:19]}{rate}" if pic else "waiting"
        )
        self.view_ops.set_visibility(self.session.operator)
        if pic is None:
            return
        key = (pic.sequence, self.ctx.jobs.ended)
        if key == self._view_shown:
            return
        self._view_shown = key
        unit = pic.width / 960.0
        overlays = [
            o
            for o in (
                map_overlay(self.ctx.jobs.result(CellCommands.map), pic.scale, unit),
                cubes_overlay(self.ctx.jobs.result(CellCommands.locate), pic.scale, unit),
            )
            if o is not None
        ]
        self.view.set_source(pic.data_url)
        self.view.content = "".join(o.svg for o in overlays)
        self.view_legend.text = "; ".join(o.legend for o in overlays)

    # -- acting ---------------------------------------------------------------------------

    async def stop(self) -> None:
        if await self.session.send(call_of(CellCommands.stop)) is not None:
            self.session.say("stop sent: the job and the arm stop", "warning")

    async def estop(self) -> None:
        if await self.session.send(call_of(CellCommands.estop)) is not None:
            self.session.say(
                "E-stop sent: everything stopped, the cell latched in fault", "warning"
            )

    async def sign_in(self) -> None:
        typed = str(self.token_input.value or "")
        try:
            await run.io_bound(self.ctx.operators.sign_in, self.browser, typed)
        except SignInError as exc:
            self.session.say(f"sign-in refused: {exc}", "negative")
            return
        finally:
            self.token_input.value = ""
        self.session.say("signed in as operator", "positive")
        self.refresh()

    def sign_out(self) -> None:
        self.ctx.operators.sign_out(self.browser)
        self.session.say("signed out: read-only")
        self.refresh()

    async def acknowledge(self) -> None:
        token = self.session.token()  # signed in, before the question
        if token is None or not await confirm("Accept the drift and allow motion again?"):
            return
        if await self.session.send(call_of(CellCommands.acknowledge_drift), token) is not None:
            self.session.say("drift acknowledged: motion allowed again")

    async def reset(self) -> None:
        if await self.session.operator_send(call_of(CellCommands.reset)) is not None:
            self.session.say("reset: the cell left the stopped/fault state")

    def start_recovery(self) -> None:
        if self.session.token() is not None:
            self.recovery.open()

    def map_line(self) -> None:
        self.session.start_job(call_of(CellCommands.map, MapRequest(points=True)))

    def locate(self) -> None:
        self.session.start_job(call_of(CellCommands.locate))

    async def start_sort(self) -> None:
        token = self.session.token()
        if token is None or self.sort_fields is None:
            return
        job = self.ctx.operators.checked(CellCommands.sort, self.sort_fields.args())
        self.sort_problems.text = "; ".join(job) if isinstance(job, list) else ""
        if isinstance(job, list):
            self.session.say(f"sort: not sent: {self.sort_problems.text}", "negative")
            return
        snap = self.ctx.link.snapshot
        if snap.status is None:
            self.session.unreachable(job.command)
            return
        if (busy := self.ctx.jobs.busy(self.browser)) is not None:
            self.session.say(f"sort: not sent: {busy}")
            return
        if snap.status["state"] not in ("idle", "stopped"):
            self.session.say(f"sort: not sent: the cell is {snap.status['state']}", "negative")
            return
        if not await confirm("Start sorting? The arm will move."):
            self.session.say("sort: cancelled, nothing was sent")
            return
        self.session.start_job(job)


def cell_page(ctx: UiContext) -> None:
    """Build the page for this browser and keep it fresh."""
    page = CellPage(ctx, str(app.storage.browser["id"]))
    page.build()
    page.refresh()
    every = page.session.every
    every(ctx.config.status_period_s, page.refresh)
    every(min(ctx.config.view_period_s, 0.5), page.refresh_view)
    for panel in (page.recovery, page.commissioning, page.cell_3d, page.simulator):
        if panel is not None:
            every(0.5, panel.refresh)
    ui.timer(page.session.tick_s, page.session.tick)  # the page's one timer
    page.watch_feed(True)  # the Cell tab is shown first
    ui.context.client.on_delete(lambda: page.watch_feed(False))
