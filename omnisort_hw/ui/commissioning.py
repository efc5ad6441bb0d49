"""Commissioning: a cell set up from nothing, step by step, each step judged against its
criteria (docs/commissioning.md) by the verdict the service gives with its reply.

1. Camera intrinsics: views taken from the live camera (`views add`, the board's detection
   drawn live with the image circle's rim coverage under it), then `calibrate what=intrinsics`
   from them: the RMS, the cross-validated RMS, the rejected views and why, the report and
   the projection uncertainty map.
2. Camera and laser plane: the target placed with its detection drawn live, then
   `calibrate what=extrinsics`: the parameters with their sigmas beside the residual picture;
   accept or retake.
3. Robot registration from the floor board, its detection drawn live (`register_robot`).
4. Verification: `map` and `locate` of what is in front of the camera, with their verdicts.
5. Saved versions: each file's kept versions (`history`), and going back to one (`adopt`).

Every action is a command of the protocol; the page only shows the replies.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

from nicegui import background_tasks, ui

from omnisort_hw.pipeline.replies import (
    AdoptReply,
    ExtrinsicsReply,
    IntrinsicsReply,
    LocateReply,
    MapReply,
    ViewsReply,
)
from omnisort_hw.pipeline.requests import DEFAULT_BOARD, DetectRequest, MapRequest
from omnisort_hw.ui.calibration_views import (
    extrinsics_args,
    parameter_rows,
    parameter_table,
    separation_input,
)
from omnisort_hw.ui.detection_view import LiveDetection
from omnisort_hw.ui.guided_step import GuidedStep, verdict_text
from omnisort_hw.ui.history_panel import HistoryPanel
from omnisort_hw.ui.job_runner import JobWatch
from omnisort_hw.ui.link import Call, CellCommands, call_of
from omnisort_hw.ui.overlay_svg import Overlay, coverage_overlay
from omnisort_hw.ui.pictures import show_picture
from omnisort_hw.ui.schema_form import typed_number
from omnisort_hw.ui.session import BrowserSession
from omnisort_hw.ui.widgets import number_input, tag

STEPS = (
    "Camera intrinsics",
    "Camera and laser plane",
    "Robot registration",
    "Verification",
    "Saved versions",
)
VERIFY = ("laser-map", "cube-location")  # the verification's steps
BOARD_DOWN = (
    "put the board down, out of the camera's view, before the next step: the target and the "
    "floor board must be seen alone"
)


def intrinsics_lines(result: IntrinsicsReply) -> list[str]:
    """The intrinsics' figures a technician judges: the RMS against its cross-validated twin,
    the views used, and each rejected view with its reason."""
    cv = result.cross_validation.rms_px
    lines = [
        f"RMS {result.rms_px:.3f} px over {result.images_used} views; cross-validated RMS "
        + (f"{cv:.3f} px" if cv is not None else "not computed (fewer than 4 views)")
    ]
    for rejected in result.images_rejected:
        lines.append(f"rejected {rejected.file.rsplit('/', 1)[-1]}: {rejected.reason}")
    return lines


class CommissioningPanel:
    """The commissioning steps; `refresh()` (a timer) follows the job a step started."""

    def __init__(
        self,
        session: BrowserSession,
        next_pose: Callable[[], Awaitable[str]] | None = None,
    ) -> None:
        """`session`: the browser's (its token, its one way to start a job and to send a quick
        command, its way to switch the laser, its id for the log); `next_pose`: with a
        simulated cell, the Simulator tab's way to walk the held board on to its next pose
        (what it says is shown under the views), so the views are taken from this tab."""
        self.session, self.ctx, self.next_pose = session, session.ctx, next_pose
        self.token, self.send, self.laser = session.token, session.operator_send, session.laser
        self.watch = JobWatch(self.ctx.jobs, session.start_job)
        self.views: ViewsReply | None = None  # the last `views` reply
        self.visible = False

        def step(name: str, note: str, go: str | None, go_tag: str) -> GuidedStep:
            go_on = self._next if go is not None else self._verified
            return GuidedStep(f"commissioning: {name}", note, go, go_tag, go_on, session.browser)

        self.steps = {
            "intrinsics": step("camera intrinsics", "intr-note", "Next", "intr-next"),
            "extrinsics": step("camera and laser plane", "extr-note", "Accept", "extr-next"),
            "robot": step("robot registration", "reg-note", "Next", "reg-next"),
            "laser-map": step("laser map", "verify-map-note", None, "verify-map-accept"),
            "cube-location": step(
                "cube location", "verify-locate-note", None, "verify-locate-accept"
            ),
        }
        self._what = ""  # the step whose job is being followed
        self.board_detection = LiveDetection(
            session, self._board_args, "intr-detect", self._coverage
        )
        self.target_detection = LiveDetection(session, DetectRequest, "extr-detect")
        self.floor_detection = LiveDetection(
            session, lambda: DetectRequest(what="floor"), "reg-detect"
        )
        self.detections = (self.board_detection, self.target_detection, self.floor_detection)
        self.history = HistoryPanel(self.send, lambda job: self._start("restore", job))

    # -- building -------------------------------------------------------------------------

    def build(self) -> None:
        with ui.stepper().props("vertical flat").classes("w-full") as self.stepper:
            with ui.step(STEPS[0]):
                self._build_intrinsics()
            with ui.step(STEPS[1]):
                self._build_extrinsics()
            with ui.step(STEPS[2]):
                self._build_registration()
            with ui.step(STEPS[3]):
                self._build_verification()
                tag(ui.button("Saved versions", on_click=self.stepper.next), "to-history")
            with ui.step(STEPS[4]):
                self.history.build()
        self.stepper.on_value_change(lambda _: self._follow_step())

    def _build_intrinsics(self) -> None:
        ui.label(
            "Hold the checkerboard in the camera's view, whole, at another place and angle for "
            "each view; reach the rim of the image circle (red sectors) as well as its centre."
        )
        with ui.row().classes("items-center gap-4"):
            self.board = tag(ui.input("board (inner corners)", value=DEFAULT_BOARD), "board")
            self.square = number_input("square (mm)", "square")
        self.board_detection.build()
        with ui.row().classes("items-center"):
            if self.next_pose is not None:
                tag(
                    ui.button("Next board pose (simulator)", on_click=self.hold_next_pose),
                    "intr-next-pose",
                ).props("outline")
            tag(ui.button("Add view", on_click=self.add_view), "add-view")
            tag(ui.button("Remove last", on_click=self.remove_last).props("flat"), "remove-view")
            tag(ui.button("Clear views", on_click=self.clear_views).props("flat"), "clear-views")
        self.pose_note = tag(ui.label(""), "intr-pose-note")
        self.views_note = tag(ui.label(""), "views-note").classes("whitespace-pre-line")
        with ui.row().classes("items-center"):
            tag(ui.button("Calibrate", on_click=self.calibrate_intrinsics), "calibrate-intr")
            self.steps["intrinsics"].build_buttons()
        self.steps["intrinsics"].build_note()
        with ui.row().classes("w-full no-wrap gap-2"):
            self.intr_report = tag(ui.image().classes("w-1/2"), "intr-report")
            self.intr_uncertainty = tag(ui.image().classes("w-1/2"), "intr-uncertainty")

    def _build_extrinsics(self) -> None:
        ui.label(
            "Place the calibration target in the camera's view with the laser on, until its "
            "markers, borders, floor lines and stripe are drawn; then calibrate."
        )
        self.target_detection.build()
        self.separation = separation_input("extr-separation")
        with ui.row().classes("items-center"):
            tag(ui.button("Laser on", on_click=lambda: self.laser(True)), "commission-laser")
            tag(ui.button("Calibrate", on_click=self.calibrate_extrinsics), "calibrate-extr")
            self.steps["extrinsics"].build_buttons()
        self.steps["extrinsics"].build_note()
        with ui.row().classes("w-full no-wrap gap-2"):
            self.extr_params = parameter_table("extr-params")
            self.extr_picture = tag(ui.image().classes("grow"), "extr-picture")

    def _build_registration(self) -> None:
        ui.label(
            "Clear the floor board of the target and anything else: the robot base is "
            "registered from it, with the laser off."
        )
        self.floor_detection.build()
        with ui.row().classes("items-center"):
            tag(ui.button("Register", on_click=self.register), "commission-register")
            self.steps["robot"].build_buttons()
        self.steps["robot"].build_note()

    def _build_verification(self) -> None:
        ui.label(
            "Put known objects (the cubes) in front of the camera: the laser map and the "
            "location must pass before the cell sorts."
        )
        with ui.row().classes("items-center"):
            tag(ui.button("Map the laser line", on_click=self.verify_map), "verify-map")
            tag(ui.button("Locate the cubes", on_click=self.verify_locate), "verify-locate")
        for what in VERIFY:
            self.steps[what].build_note()
            self.steps[what].build_buttons()
        self.commissioned = tag(ui.label(""), "commissioned").classes("font-bold")

    # -- showing --------------------------------------------------------------------------

    def show(self, visible: bool) -> None:
        """The panel is shown (its tab open): its step's live detection asks the service."""
        self.visible = visible
        self._follow_step()

    def _follow_step(self) -> None:
        step = STEPS.index(self.stepper.value) if self.stepper.value in STEPS else 0
        for i, detection in enumerate(self.detections):
            detection.active = self.visible and i == step
        if self.visible and step == STEPS.index("Saved versions"):
            background_tasks.create(self.history.load(), name="history")

    def _next(self) -> None:
        self.stepper.next()

    def _verified(self) -> None:
        """The verdict line once the map and the location have each passed or been accepted."""
        if all(self.steps[k].accepted for k in VERIFY):
            self.commissioned.text = "Commissioned: every step passed; the cell may sort."

    def _board_size(self) -> str:
        return str(self.board.value or DEFAULT_BOARD)

    def _board_args(self) -> DetectRequest:
        return DetectRequest(what="board", board=self._board_size())

    def _coverage(self, scale: float, unit: float) -> Overlay | None:
        return coverage_overlay(self.views, scale, unit) if self.views else None

    def _show_views(self, reply: ViewsReply) -> None:
        self.views = reply
        names = ", ".join(v.name for v in reply.views) or "none"
        self.views_note.text = f"views kept: {names}\n{verdict_text(reply.verdict)}"

    # -- acting: the views ------------------------------------------------------------------

    async def _views(self, args: dict[str, Any]) -> None:
        """One `views` request, checked against its schema first; its reply shown."""
        job = self.ctx.operators.checked(CellCommands.views, args)
        if isinstance(job, list):
            self.views_note.text = "not sent: " + "; ".join(job)
            return
        reply = await self.send(job)
        if reply is not None:
            self._show_views(reply)

    async def hold_next_pose(self) -> None:
        """The simulated board walked on to its next pose, said under the views."""
        if self.next_pose is not None:
            self.pose_note.text = await self.next_pose()

    async def add_view(self) -> None:
        await self._views({"action": "add", "board": self._board_size()})

    async def remove_last(self) -> None:
        if self.views is not None and self.views.views:
            await self._views({"action": "remove", "name": self.views.views[-1].name})

    async def clear_views(self) -> None:
        await self._views({"action": "clear"})

    async def load_views(self) -> None:
        """The views already kept (a page opened after some were taken)."""
        if self.token() is not None and not self.views:
            await self._views({"action": "list"})

    # -- acting: the jobs -------------------------------------------------------------------

    def _start(self, what: str, job: Call[object] | list[str], doing: str = "") -> bool:
        """Start a step's job (`what`: the step; `restore` has none), or (`job` a list: what
        its command's schema found wrong with the form) show why not (`GuidedStep.start`)."""
        step = self.steps.get(what)
        if step is not None:
            started = step.start(self.watch, job, doing)
        else:
            started = not isinstance(job, list) and self.watch.start(job)
        if started:
            self._what = what
            if what in VERIFY:
                self.commissioned.text = ""
        return started

    def calibrate_intrinsics(self) -> None:
        args = {
            "what": "intrinsics",
            "folder": self.views.folder if self.views else "",
            "board": self._board_size(),
            "square_mm": typed_number(self.square.value),
        }
        doing = f"calibrating the lens from {self.views.count if self.views else 0} views..."
        self._start("intrinsics", self.ctx.operators.checked(CellCommands.calibrate, args), doing)

    def calibrate_extrinsics(self) -> None:
        job = self.ctx.operators.checked(CellCommands.calibrate, extrinsics_args(self.separation))
        self._start("extrinsics", job, "calibrating camera and laser plane...")

    def register(self) -> None:
        doing = "registering the robot base from the floor board..."
        self._start("robot", call_of(CellCommands.register_robot), doing)

    def verify_map(self) -> None:
        job = call_of(CellCommands.map, MapRequest(points=True))
        self._start("laser-map", job, "mapping the laser line...")

    def verify_locate(self) -> None:
        self._start("cube-location", call_of(CellCommands.locate), "locating the cubes...")

    async def refresh(self) -> None:
        """When the job a step started has ended: show its reply and verdict, or its error."""
        if not self.views and self.visible:
            await self.load_views()
        end = self.watch.ended()
        if end is None:
            if self.watch.waiting and self._what in self.steps:
                self.steps[self._what].running(self.ctx.link.running_job())
            return
        what = self._what
        if what == "restore":
            adopted = end.result if isinstance(end.result, AdoptReply) else None
            await self.history.ended(end.ok, end.message, adopted)
            return
        step = self.steps[what]
        result = end.result if end.ok else None
        level = step.ended(end, self._lines(result))
        await self._show_pictures(result, step.note)
        if what in VERIFY and level == "pass":
            self._verified()

    @staticmethod
    def _lines(result: object) -> list[str]:
        """A step's own figures under its verdict (its reply's record says which step)."""
        if isinstance(result, IntrinsicsReply):
            failed = result.verdict.level == "fail"
            return intrinsics_lines(result) + ([] if failed else [BOARD_DOWN])
        if isinstance(result, MapReply):
            return [f"{result.points_on_plane} points on the laser plane"]
        if isinstance(result, LocateReply):
            return [f"{result.count} cubes located"]
        return []

    async def _show_pictures(self, result: object, note: Any) -> None:
        pictures: list[tuple[str | None, Any]] = []
        if isinstance(result, IntrinsicsReply):
            pictures = [(result.report, self.intr_report)]
            pictures.append((result.uncertainty_png, self.intr_uncertainty))
        elif isinstance(result, ExtrinsicsReply):
            self.extr_params.rows = parameter_rows(result)
            self.extr_params.update()
            pictures = [(result.overlay_png, self.extr_picture)]
        for path, image in pictures:  # after the note: a picture not sent says so in it
            await show_picture(self.ctx, self.token(), path, image, note)
