"""The guided recovery after a bump: when the drift watchdog refuses motion, the operator is
led through placing the target, calibrating the camera and the laser plane again (the
parameters with their sigmas and the residual picture; accept or retake), registering the
robot again, and a check that finds no drift, then sorts again. Each step is one command of the
protocol (`calibrate what=extrinsics`, `register_robot`, `check`); the page only shows their
replies. Started from the drift banner; open to a signed-in operator."""

from __future__ import annotations

from nicegui import ui

from omnisort_hw.pipeline.replies import DriftReply, ExtrinsicsReply
from omnisort_hw.pipeline.requests import DetectRequest
from omnisort_hw.ui.calibration_views import (
    extrinsics_args,
    parameter_rows,
    parameter_table,
    separation_input,
)
from omnisort_hw.ui.detection_view import LiveDetection
from omnisort_hw.ui.guided_step import GuidedStep
from omnisort_hw.ui.job_runner import JobWatch
from omnisort_hw.ui.link import Call, CellCommands, call_of
from omnisort_hw.ui.pictures import show_picture
from omnisort_hw.ui.session import BrowserSession
from omnisort_hw.ui.widgets import tag

STEPS = ("Place the target", "Calibrate camera and laser", "Register the robot", "Verify")


class RecoveryPanel:
    """The recovery's steps on one page; `refresh()` follows the job each step started."""

    def __init__(self, session: BrowserSession) -> None:
        """`session`: the browser's (its token, its way to start a job and to switch the
        laser, its id for the log)."""
        self.session, self.ctx = session, session.ctx
        self.token, self.laser = session.token, session.laser
        self.watch = JobWatch(self.ctx.jobs, session.start_job)
        self.active = False  # opened from the drift banner, until the operator closes it
        self._step = "recalibration"  # the step whose job was started last
        self.detection = LiveDetection(session, DetectRequest, "recovery-target")
        self.steps = {
            "recalibration": GuidedStep(
                "recovery: camera and laser plane",
                "calib-note",
                "Accept",
                "accept-calib",
                self._next,
                session.browser,
            ),
            "robot": GuidedStep(
                "recovery: robot registration",
                "register-note",
                "Next",
                "accept-register",
                self._next,
                session.browser,
            ),
            "verify": GuidedStep(
                "recovery: drift check",
                "check-note",
                "Done",
                "recovery-done",
                self.close,
                session.browser,
            ),
        }

    def _next(self) -> None:
        self.stepper.next()

    def build(self) -> None:
        steps = self.steps
        with tag(ui.card(), "recovery").classes("w-full") as self.card:
            ui.label("Recovery after a bump").classes("text-lg")
            with ui.stepper().props("vertical flat").classes("w-full") as self.stepper:
                with ui.step(STEPS[0]):
                    ui.label(
                        "The camera turned since its calibration: motion is refused until the "
                        "camera and the laser plane are calibrated again and the robot is "
                        "registered again. Place the calibration target in the camera's view, "
                        "with the laser on, until its detection (markers, borders, floor lines "
                        "and stripe) is drawn below; clear the floor board."
                    )
                    self.detection.build()
                    with ui.stepper_navigation():
                        tag(
                            ui.button("Laser on", on_click=lambda: self.laser(True)),
                            "recovery-laser",
                        )
                        tag(ui.button("Target placed", on_click=self.placed), "placed")
                with ui.step(STEPS[1]):
                    self.separation = separation_input("calib-separation")
                    steps["recalibration"].build_note()
                    self.params = parameter_table("calib-params")
                    self.residuals = tag(
                        ui.image().classes("w-full max-w-[960px]"), "calib-picture"
                    )
                    with ui.stepper_navigation():
                        tag(ui.button("Calibrate", on_click=self.calibrate), "calibrate")
                        steps["recalibration"].build_buttons()
                with ui.step(STEPS[2]):
                    steps["robot"].build_note()
                    with ui.stepper_navigation():
                        tag(ui.button("Register", on_click=self.register), "register")
                        steps["robot"].build_buttons()
                        self._back("back-to-calib")
                with ui.step(STEPS[3]):
                    steps["verify"].build_note()
                    with ui.stepper_navigation():
                        tag(ui.button("Check", on_click=self.check), "check")
                        steps["verify"].build_buttons()
                        self._back("back-to-register")
        self.card.set_visibility(False)

    def _back(self, name: str) -> None:
        """Back to the step before, to retake it (a warning accepted, then thought better of)."""
        tag(ui.button("Back", on_click=self.stepper.previous).props("flat"), name)

    def show(self, visible: bool) -> None:
        self.card.set_visibility(visible)

    def open(self) -> None:
        """From the first step."""
        self.active = True
        self.detection.active = True
        self.stepper.set_value(STEPS[0])
        for step in self.steps.values():
            step.reset()
        self.card.set_visibility(True)

    def close(self) -> None:
        self.active = False
        self.detection.active = False
        self.card.set_visibility(False)

    def placed(self) -> None:
        """On to the calibration; the live detection stops asking."""
        self.detection.active = False
        self.stepper.next()

    def _start(self, step: str, job: Call[object] | list[str], doing: str) -> None:
        if self.steps[step].start(self.watch, job, doing):
            self._step = step

    def calibrate(self) -> None:
        job = self.ctx.operators.checked(CellCommands.calibrate, extrinsics_args(self.separation))
        self._start("recalibration", job, "calibrating from a capture of the target...")

    def register(self) -> None:
        job = call_of(CellCommands.register_robot)
        self._start("robot", job, "registering the robot from the floor board...")

    def check(self) -> None:
        job = call_of(CellCommands.check)
        self._start("verify", job, "checking the camera against the new calibration...")

    async def refresh(self) -> None:
        """When the job a step started has ended: show its reply, or its error."""
        end = self.watch.ended()
        if end is None:
            if self.watch.waiting:
                self.steps[self._step].running(self.ctx.link.running_job())
            return
        step, result = self.steps[self._step], end.result if end.ok else None
        if isinstance(result, DriftReply):
            turned = "DRIFT" if result.drift else "no drift"
            step.ended(end, [f"{turned}: turned {result.angle_deg:.3f} deg"])
            return
        step.ended(end)
        if isinstance(result, ExtrinsicsReply):
            self.params.rows = parameter_rows(result)
            self.params.update()
            await show_picture(
                self.ctx, self.token(), result.overlay_png, self.residuals, step.note
            )
