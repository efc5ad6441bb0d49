"""The simulator's control panel (the Simulator tab, shown when `[ui] sim_control` names a
virtual cell's control channel): for the researcher and the student, what the published
simulator's panels did with the mouse, and what a person does to a real cell.

- the camera's mounting (roll, pitch, yaw) and a knock, to rehearse the recovery;
- the board held in front of the camera for the intrinsics' views;
- the laser: switched, turned and moved;
- the calibration target: its kind, where it stands, or taken away;
- the cubes: moved, added, taken away;
- the arm jogged by joints or to an XYZ of its base through the core's inverse kinematics,
  and the gripper (each asked to be confirmed: the simulated arm moves);
- pictures rendered with the renderer's truth beside them, singly or the board's poses.

Every action is one control-channel command (`SimLink`); the panel shows the virtual cell's
own truth after it. Nothing goes through the service: it sees the changes as a real cell's
would show them, through its camera, laser and arm. Only a signed-in operator acts.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from nicegui import run, ui

from omnisort_hw import sim_requests as sr
from omnisort_hw.request_fields import build
from omnisort_hw.sim_link import MOVE_TIMEOUT_S, SimControlError, SimLink
from omnisort_hw.sim_replies import SimDescription, SimShown, SimTruth
from omnisort_hw.ui.schema_form import form_fields, problems, typed_number
from omnisort_hw.ui.schema_widgets import SchemaForm
from omnisort_hw.ui.session import BrowserSession
from omnisort_hw.ui.widgets import confirm, tag
from omnisort_hw.wire_records import to_wire

CUBE_COLUMNS = [
    {"name": k, "label": label, "field": k, "align": "left"}
    for k, label in (
        ("index", "cube"),
        ("color", "colour"),
        ("x", "x (S), mm"),
        ("y", "y (S), mm"),
        ("bin", "in bin"),
    )
]
DECIDED_BY_BUTTONS = {"cube": ("action",), "gripper": ("closed",), "render": ("views",)}
"""Arguments a form leaves to its buttons (Move, Add, Remove; Close, Open; one picture or the
board's poses)."""


def truth_lines(truth: SimTruth) -> list[str]:
    """The virtual cell's truth as a person reads it: the camera's mounting, the laser plane,
    the arm and the gripper."""
    cam, laser, target = truth.camera, truth.laser, truth.target
    lines = [
        f"camera: roll {cam.roll_deg:.3f}, pitch {cam.pitch_deg:.3f}, yaw {cam.yaw_deg:.3f} deg",
        f"laser: {'on' if truth.laser_on else 'off'}, roll {laser.roll_deg:.2f}, "
        f"pitch {laser.pitch_deg:.2f} deg, {laser.distance_mm:.1f} mm below the camera",
        "target: away"
        if target is None
        else "target: {}, centre {:.0f}, {:.0f} mm, yaw {:.1f} deg".format(
            target.kind, *target.center_mm, target.yaw_deg
        ),
    ]
    if truth.joints_deg:
        lines.append("arm joints: " + ", ".join(f"{q:.1f}" for q in truth.joints_deg) + " deg")
    lines.append("tool at " + ", ".join(f"{v:.1f}" for v in truth.tcp_B_mm) + " mm (base)")
    lines.append(
        "gripper: "
        + ("closed" if truth.gripper_closed else "open")
        + (", holding a cube" if truth.held else "")
    )
    if truth.collisions:
        lines.append(f"collisions: {truth.collisions}")
    return lines


def cube_rows(truth: SimTruth) -> list[dict[str, object]]:
    """The cubes table's rows."""
    return [
        {
            "index": c.index,
            "color": c.color,
            "x": round(c.center_S_mm[0], 1),
            "y": round(c.center_S_mm[1], 1),
            "bin": c.bin or "",
        }
        for c in truth.cubes
    ]


class _Shown(dict[str, object]):
    """A note's values: what was not given was left as it was."""

    def __missing__(self, key: str) -> str:
        return "as it was"


class SimulatorPanel:
    """The Simulator tab's controls; `refresh()` (a timer) shows the live picture and, every
    few seconds while the tab is shown, the truth. Each command's fields are drawn from the
    channel's own `describe` (`SchemaForm`) once the tab is first shown; the buttons are the
    panel's."""

    def __init__(self, session: BrowserSession, sim: SimLink) -> None:
        """`session`: the browser's (its token: None, with why said, when not signed in)."""
        self.ctx, self.sim, self.token = session.ctx, sim, session.token
        self.visible = False
        self._ticks = 0
        self._busy = False
        self._shown = -1
        self._filled = False  # the forms start from the cell as it is, once
        self._schemas: dict[str, Any] = {}  # each command's, from the channel's describe
        self._slots: dict[str, ui.row] = {}  # each command's row, where its fields are drawn
        self.forms: dict[str, SchemaForm] = {}
        self._describing = asyncio.Lock()

    # -- building -------------------------------------------------------------------------

    def build(self) -> None:
        with ui.row().classes("w-full items-start gap-4 no-wrap"):
            with ui.column().classes("gap-2 w-[34rem]"):
                self._card("Camera", [("camera", "Mount", "sim-mount", self.mount)])
                self._card("Knock", [("knock", "Knock", "sim-knock", self.knock)], "amber-9")
                self._card(
                    "Board held for the views",
                    [
                        ("board", "Hold", "sim-board", self.hold_board),
                        ("", "Next pose", "sim-board-next", self.next_board),
                        ("", "Put down", "sim-board-down", self.put_board_down),
                    ],
                )
                self._card("Laser", [("laser", "Set", "sim-laser", self.set_laser)])
                self._card("Calibration target", [("target", "Set", "sim-target", self.set_target)])
                self._card(
                    "Cubes",
                    [
                        ("cube", "Move", "sim-cube-move", lambda: self.cube("move")),
                        ("", "Add", "sim-cube-add", lambda: self.cube("add")),
                        ("", "Remove", "sim-cube-remove", lambda: self.cube("remove")),
                    ],
                )
                self._card(
                    "Arm (from the pendant)",
                    [
                        ("joints", "Move joints", "sim-joints", self.move_joints),
                        ("", "Read joints", "sim-read", self.read_joints),
                    ],
                )
                self._card("Tool", [("move_to", "Move to", "sim-move-to", self.move_to)])
                self._card(
                    "Gripper",
                    [
                        ("", "Close gripper", "sim-close", lambda: self.gripper(True)),
                        ("", "Open gripper", "sim-open", lambda: self.gripper(False)),
                    ],
                )
                self._card(
                    "Pictures with their truth",
                    [
                        ("render", "Render", "sim-render", self.render),
                        ("", "Render the board's poses", "sim-render-views", self.render_views),
                    ],
                )
            with ui.column().classes("gap-2 grow min-w-0"):
                self.note = tag(ui.label(""), "sim-note").classes("whitespace-pre-line")
                self.picture = tag(
                    ui.interactive_image().classes("w-full max-w-[640px]"), "sim-view"
                )
                self.truth = tag(ui.label(""), "sim-truth").classes("whitespace-pre-line")
                self.cubes = tag(
                    ui.table(columns=CUBE_COLUMNS, rows=[], row_key="index").props("dense flat"),
                    "sim-cubes",
                )

    def _card(
        self,
        title: str,
        buttons: list[tuple[str, str, str, Callable[[], object]]],
        color: str | None = None,
    ) -> None:
        """A card with its title, a row for each command's fields (`(command, label, name,
        action)`; "" for a button of the command before) and its buttons."""
        with ui.card().classes("w-full"):
            ui.label(title).classes("text-lg")
            for cmd, _, _, _ in buttons:
                if cmd:
                    self._slots[cmd] = ui.row().classes("items-center")
            with ui.row().classes("items-center"):
                for i, (_, label, name, action) in enumerate(buttons):
                    button = ui.button(label, on_click=action)
                    if i > 0:
                        button.props("flat")
                    elif color is not None:
                        button.props(f"color={color}")
                    tag(button, name)

    async def _forms(self) -> bool:
        """The channel's schemas read (its `describe`, once) and each command's fields drawn
        from its own; False, with why in the note, when the channel did not describe them."""
        async with self._describing:  # the timer and a button may both ask first
            if self._schemas:
                return True
            described = await self._control(sr.DescribeRequest())
            if not isinstance(described, SimDescription):
                return False
            self._schemas = {k: v.args for k, v in described.commands.items()}
            for cmd, slot in self._slots.items():
                skip = DECIDED_BY_BUTTONS.get(cmd, ())
                fields = [f for f in form_fields(self._schemas[cmd]) if f.name not in skip]
                with slot:
                    self.forms[cmd] = SchemaForm(fields, f"sim-{cmd}", "w-36")
        return True

    # -- reading --------------------------------------------------------------------------

    def show(self, visible: bool) -> None:
        self.visible = visible
        if visible:
            self._ticks = 0

    async def refresh(self) -> None:
        """The live picture (the service's, as every page gets it) and, every 4th tick, the
        virtual cell's truth, while the tab is shown."""
        if not self.visible:
            return
        pic = self.ctx.feed.picture
        if pic is not None and pic.sequence != self._shown:
            self._shown = pic.sequence
            self.picture.set_source(pic.data_url)
        self._ticks += 1
        if self._ticks % 4 == 1 and not self._busy and await self._forms():
            await self._show_truth()

    async def _show_truth(self, quiet: bool = True) -> SimTruth | None:
        """The virtual cell's truth asked and shown (the forms filled from it the first time)."""
        truth = await self._control(sr.TruthRequest(), quiet=quiet)
        if not isinstance(truth, SimTruth):
            return None
        if not self._filled:
            self._fill(truth)
        self.truth.text = "\n".join(truth_lines(truth))
        rows = cube_rows(truth)
        if rows != self.cubes.rows:
            self.cubes.rows = rows
            self.cubes.update()
        return truth

    def _fill(self, truth: SimTruth) -> None:
        """The forms set to the virtual cell as it is: the camera's mounting, the laser, the
        target, the joints and the tool (so a first Set or Move changes only what the person
        changes)."""
        self._filled = True
        cam, laser, target = truth.camera, truth.laser, truth.target
        values: dict[str, dict[str, Any]] = {
            "camera": {
                "roll_deg": cam.roll_deg,
                "pitch_deg": cam.pitch_deg,
                "yaw_deg": cam.yaw_deg,
            },
            "laser": {
                "on": truth.laser_on,
                "roll_deg": laser.roll_deg,
                "pitch_deg": laser.pitch_deg,
                "distance_mm": laser.distance_mm,
            },
            "target": {"on": target is not None},
            "joints": {"q_deg": truth.joints_deg},
            "move_to": dict(zip(("x_mm", "y_mm", "z_mm"), truth.tcp_B_mm, strict=True)),
        }
        if target is not None:
            x, y = target.center_mm
            values["target"] |= {
                "kind": target.kind,
                "x_mm": x,
                "y_mm": y,
                "yaw_deg": target.yaw_deg,
            }
        for cmd, fields in values.items():
            form = self.forms.get(cmd)
            for name, value in fields.items():
                if form is not None and name in form.inputs:
                    form.set(name, value)

    # -- acting ---------------------------------------------------------------------------

    async def _control(self, request: Any, quiet: bool = False) -> object | None:
        """The control-channel command of a request record (`SimLink.send`); its reply as the
        record its command declares, or None with why in the note (refused, unreachable, or a
        reply that does not fit: a virtual cell of another version)."""
        self._busy = True
        try:
            return await run.io_bound(self.sim.send, request, MOVE_TIMEOUT_S)
        except SimControlError as exc:
            if not quiet:
                cmd = sr.command_of(request)
                self.note.text = f"{cmd}: refused by the virtual cell {exc.address}: {exc.message}"
            return None
        finally:
            self._busy = False

    async def _act(
        self, request: type[Any], done: str, moves: str | None = None, **fixed: Any
    ) -> None:
        """A signed-in operator's command, named by its request record's class, with its form's
        arguments and `fixed` (what the button decides): checked against the channel's schema
        (nothing sent when it refuses, each problem naming its field), confirmed when it
        `moves` the arm (the question), sent as the record, then the note and the truth after
        it."""
        cmd = sr.command_of(request)
        if self.token() is None:
            self.note.text = f"{cmd}: sign in as operator first: nothing was sent"
            return
        if not await self._forms():
            return
        schema = self._schemas[cmd]
        form = self.forms.get(cmd)
        given = form.args(schema, **fixed) if form is not None else dict(fixed)
        found = problems(schema, given)
        if found:
            self.note.text = f"{cmd}: not sent: " + "; ".join(found)
            return
        if moves is not None and not await confirm(f"{moves}? The simulated arm will move."):
            self.note.text = "cancelled: nothing was sent"
            return
        self.note.text = f"{cmd} ..."
        reply = await self._control(build(request, given))
        if reply is None:
            return
        unseen = isinstance(reply, SimShown) and not reply.shown
        shown = " (no picture shows it yet)" if unseen else ""
        self.note.text = done.format_map(_Shown({**given, **to_wire(reply)})) + shown
        await self._show_truth()

    async def mount(self) -> None:
        done = "camera mounted at roll {roll_deg:g}, pitch {pitch_deg:g}, yaw {yaw_deg:g} deg"
        await self._act(sr.CameraRequest, done)

    async def knock(self) -> None:
        await self._act(sr.KnockRequest, "camera knocked by {angle_deg:g} deg about {axis}")

    async def hold_board(self) -> None:
        if await self._forms():
            held = self._view() is not None
            await self._act(
                sr.BoardRequest, "board held at pose {view}" if held else "board put down"
            )

    def _view(self) -> int | None:
        """The board's pose typed (None: none, or not a whole number)."""
        value = typed_number(self.forms["board"].typed()["view"], integer=True)
        return value if isinstance(value, int) else None

    async def next_board(self) -> str:
        """The board moved on to its next pose, as a person walks it through the field; after
        the last, the first again (said in the note); the note."""
        if not await self._forms():
            return str(self.note.text)
        top = sr.HELD_VIEWS - 1
        now = self._view()
        view = 0 if now is None else (now + 1) % (top + 1)
        self.forms["board"].set("view", view)
        await self.hold_board()
        if view == 0 and now == top:
            self.note.text += f" (all {top + 1} poses shown: the first again)"
        return str(self.note.text)

    async def put_board_down(self) -> None:
        if await self._forms():
            self.forms["board"].set("view", "")
            await self._act(sr.BoardRequest, "board put down")

    async def set_laser(self) -> None:
        await self._act(
            sr.LaserRequest,
            "laser on: {on}; roll {roll_deg}, pitch {pitch_deg} deg, {distance_mm} mm",
        )

    async def set_target(self) -> None:
        form = self.forms.get("target")
        if form is not None and not form.typed()["on"]:
            await self._act(sr.TargetRequest, "target taken away", on=False)
            return
        await self._act(sr.TargetRequest, "target {kind} set")

    async def cube(self, action: str) -> None:
        await self._act(sr.CubeRequest, f"cube {action}: done, cube {{index}}", action=action)

    async def read_joints(self) -> None:
        truth = await self._show_truth(quiet=False)
        if truth is not None and "joints" in self.forms:
            self.forms["joints"].set("q_deg", truth.joints_deg)

    async def move_joints(self) -> None:
        done = "arm at the joints asked ({seconds:.1f} s)"
        await self._act(sr.JointsRequest, done, "Move the arm to these joints")

    async def move_to(self) -> None:
        done = "tool at the point asked ({seconds:.1f} s)"
        await self._act(sr.MoveToRequest, done, "Move the tool to this point")

    async def gripper(self, closed: bool) -> None:
        await self._act(
            sr.GripperRequest,
            "gripper closed, holding: {holding}" if closed else "gripper open",
            "Close the gripper" if closed else "Open the gripper",
            closed=closed,
        )

    async def render(self) -> None:
        await self._act(sr.RenderRequest, "written: {images}", views=False)

    async def render_views(self) -> None:
        await self._act(sr.RenderRequest, "written: {images}", views=True)
