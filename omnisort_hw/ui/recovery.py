"""The guided recovery after a bump: when the drift watchdog refuses motion, the operator is
led through placing the target, calibrating the camera and the laser plane again (the
parameters with their sigmas and the residual picture; accept or retake), registering the
robot again, and a check that finds no drift, then sorts again. Each step is one command of the
protocol (`calibrate what=extrinsics`, `register_robot`, `check`); the page only shows their
replies. Started from the drift banner; open to a signed-in operator."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping
from typing import Any

from nicegui import ui

from omnisort_hw.pipeline.verdict import verdict_lines
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.detection_view import LiveDetection
from omnisort_hw.ui.job_runner import JobWatch
from omnisort_hw.ui.pictures import show_picture
from omnisort_hw.ui.widgets import tag

STEPS = ("Place the target", "Calibrate camera and laser", "Register the robot", "Verify")
PARAMETER_UNITS = {"_deg": "deg", "_mm": "mm"}
PARAMETER_COLUMNS = ("name", "value", "sigma")


def parameter_rows(reply: Mapping[str, Any]) -> list[dict[str, str]]:
    """An extrinsic calibration's parameters with their 1-sigma, for a table."""
    params: Mapping[str, float] = reply.get("parameters") or {}
    std: Mapping[str, float] = reply.get("std") or {}
    rows = []
    for name, value in params.items():
        unit = next((u for suffix, u in PARAMETER_UNITS.items() if name.endswith(suffix)), "")
        sigma = std.get(name)
        rows.append(
            {
                "name": name,
                "value": f"{value:.4f} {unit}".strip(),
                "sigma": f"{sigma:.4f} {unit}".strip() if sigma is not None else "not given",
            }
        )
    return rows


def parameter_table(name: str) -> Any:
    """An empty table for `parameter_rows`, named `name` for the tests."""
    columns = [{"name": k, "label": k, "field": k, "align": "left"} for k in PARAMETER_COLUMNS]
    return tag(ui.table(columns=columns, rows=[], row_key="name").props("dense flat"), name)


class RecoveryPanel:
    """The recovery's steps on one page; `refresh()` follows the job each step started."""

    def __init__(
        self,
        ctx: UiContext,
        token: Callable[[], str | None],
        start_job: Callable[[str, dict[str, Any]], bool],
        laser: Callable[[bool], Awaitable[None]],
    ) -> None:
        """`token`: this session's, for the residual picture; `start_job`: the page's one way
        to start a job (signed in, service reachable, no job of this interface running);
        `laser`: its way to switch the laser."""
        self.ctx, self.token, self.laser = ctx, token, laser
        self.watch = JobWatch(ctx.jobs, start_job)
        self.active = False  # opened from the drift banner, until the operator closes it
        self.detection = LiveDetection(ctx, token, lambda: {"what": "target"}, "recovery-target")

    def build(self) -> None:
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
                    self.calib_note = tag(ui.label(""), "calib-note")
                    self.params = parameter_table("calib-params")
                    self.residuals = tag(
                        ui.image().classes("w-full max-w-[960px]"), "calib-picture"
                    )
                    with ui.stepper_navigation():
                        tag(ui.button("Calibrate", on_click=self.calibrate), "calibrate")
                        self.accept = tag(
                            ui.button("Accept", on_click=self.stepper.next), "accept-calib"
                        )
                with ui.step(STEPS[2]):
                    self.register_note = tag(ui.label(""), "register-note")
                    with ui.stepper_navigation():
                        tag(ui.button("Register", on_click=self.register), "register")
                        self.accept_register = tag(
                            ui.button("Next", on_click=self.stepper.next), "accept-register"
                        )
                with ui.step(STEPS[3]):
                    self.check_note = tag(ui.label(""), "check-note")
                    with ui.stepper_navigation():
                        tag(ui.button("Check", on_click=self.check), "check")
                        self.done = tag(ui.button("Done", on_click=self.close), "recovery-done")
        self.done.set_visibility(False)
        self.accept.set_visibility(False)
        self.accept_register.set_visibility(False)
        self.card.set_visibility(False)

    def show(self, visible: bool) -> None:
        self.card.set_visibility(visible)

    def open(self) -> None:
        """From the first step."""
        self.active = True
        self.detection.active = True
        self.stepper.set_value(STEPS[0])
        for hidden in (self.accept, self.accept_register, self.done):
            hidden.set_visibility(False)
        self.card.set_visibility(True)

    def close(self) -> None:
        self.active = False
        self.detection.active = False
        self.card.set_visibility(False)

    def placed(self) -> None:
        """On to the calibration; the live detection stops asking."""
        self.detection.active = False
        self.stepper.next()

    def calibrate(self) -> None:
        self.accept.set_visibility(False)
        if self.watch.start("calibrate", {"what": "extrinsics"}):
            self.calib_note.text = "calibrating from a capture of the target..."

    def register(self) -> None:
        self.accept_register.set_visibility(False)
        if self.watch.start("register_robot", {}):
            self.register_note.text = "registering the robot from the floor board..."

    def check(self) -> None:
        if self.watch.start("check", {}):
            self.check_note.text = "checking the camera against the new calibration..."

    async def refresh(self) -> None:
        """When the job a step started has ended: show its reply, or its error."""
        end = self.watch.ended()
        if end is None:
            return
        cmd = end.cmd
        note = {
            "calibrate": self.calib_note,
            "register_robot": self.register_note,
            "check": self.check_note,
        }[cmd]
        if not end.ok or end.result is None:
            note.text = f"{end.message}: retake after fixing the cause"
            return
        note.text = "; ".join(self._summary(cmd, end.result))
        if cmd == "calibrate":
            self.params.rows = parameter_rows(end.result)
            self.params.update()
            await show_picture(
                self.ctx, self.token(), end.result.get("overlay_png"), self.residuals, note
            )
            self.accept.set_visibility(True)
        elif cmd == "register_robot":
            self.accept_register.set_visibility(True)
        elif cmd == "check" and not end.result.get("drift"):
            self.done.set_visibility(True)

    @staticmethod
    def _summary(cmd: str, result: Mapping[str, Any]) -> list[str]:
        lines = []
        if cmd == "check":
            turned = "DRIFT" if result.get("drift") else "no drift"
            lines.append(f"{turned}: turned {result.get('angle_deg', 0):.3f} deg")
        if isinstance(result.get("verdict"), Mapping):
            lines += [line.strip() for line in verdict_lines(result["verdict"])]
        return lines or [f"{cmd} done"]
