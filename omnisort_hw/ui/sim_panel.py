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

from collections.abc import Callable
from typing import Any

from nicegui import run, ui

from omnisort_hw import sim_requests as sr
from omnisort_hw.request_fields import build
from omnisort_hw.sim_link import MOVE_TIMEOUT_S, SimControlError, SimLink
from omnisort_hw.ui.context import UiContext
from omnisort_hw.ui.schema_form import problems, typed_number
from omnisort_hw.ui.widgets import confirm, number_input, tag

COLOURS = sr.SIM_COLORS[:4]  # the cubes the colour table sorts
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


def truth_lines(truth: dict[str, Any]) -> list[str]:
    """The virtual cell's truth as a person reads it: the camera's mounting, the laser plane,
    the arm and the gripper."""
    cam, laser = truth.get("camera_rotation") or {}, truth.get("laser_plane") or {}
    lines = [
        "camera: roll {:.3f}, pitch {:.3f}, yaw {:.3f} deg".format(
            cam.get("roll_deg", 0.0), cam.get("pitch_deg", 0.0), cam.get("yaw_deg", 0.0)
        ),
        "laser: {}, roll {:.2f}, pitch {:.2f} deg, {:.1f} mm below the camera".format(
            "on" if truth.get("laser_on") else "off",
            laser.get("roll_deg", 0.0),
            laser.get("pitch_deg", 0.0),
            laser.get("distance_mm", 0.0),
        ),
    ]
    target = truth.get("target")
    lines.append(
        "target: away"
        if not target
        else "target: {}, centre {:.0f}, {:.0f} mm, yaw {:.1f} deg".format(
            target["kind"], *target["center_mm"], target["yaw_deg"]
        )
    )
    if truth.get("joints_deg"):
        lines.append("arm joints: " + ", ".join(f"{q:.1f}" for q in truth["joints_deg"]) + " deg")
    if truth.get("tcp_B_mm"):
        lines.append("tool at " + ", ".join(f"{v:.1f}" for v in truth["tcp_B_mm"]) + " mm (base)")
    lines.append(
        "gripper: "
        + ("closed" if truth.get("gripper_closed") else "open")
        + (", holding a cube" if truth.get("held") else "")
    )
    if truth.get("collisions"):
        lines.append(f"collisions: {len(truth['collisions'])}")
    return lines


def cube_rows(truth: dict[str, Any]) -> list[dict[str, Any]]:
    return [
        {
            "index": c["index"],
            "color": c["color"],
            "x": round(c["center_S_mm"][0], 1),
            "y": round(c["center_S_mm"][1], 1),
            "bin": c.get("bin") or "",
        }
        for c in truth.get("cubes") or []
    ]


def _number(label: str, value: float, name: str, width: str = "w-24") -> Any:
    return number_input(label, name, value).classes(width)


class SimulatorPanel:
    """The Simulator tab's controls; `refresh()` (a timer) shows the live picture and, every
    few seconds while the tab is shown, the truth."""

    def __init__(self, ctx: UiContext, sim: SimLink, token: Callable[[], str | None]) -> None:
        """`token`: this session's (None, with why shown, when not signed in)."""
        self.ctx, self.sim, self.token = ctx, sim, token
        self.visible = False
        self._ticks = 0
        self._busy = False
        self._shown = -1
        self._filled = False  # the forms start from the cell as it is, once
        self._schemas: dict[str, Any] = {}  # each command's, from the channel's describe

    # -- building -------------------------------------------------------------------------

    def build(self) -> None:
        with ui.row().classes("w-full items-start gap-4 no-wrap"):
            with ui.column().classes("gap-2 w-[34rem]"):
                self._build_camera()
                self._build_laser()
                self._build_target()
                self._build_cubes()
                self._build_arm()
                self._build_render()
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

    def _build_camera(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Camera").classes("text-lg")
            with ui.row().classes("items-center"):
                self.roll = _number("roll, deg", 0.0, "sim-roll")
                self.pitch = _number("pitch, deg", 0.0, "sim-pitch")
                self.yaw = _number("yaw, deg", 0.0, "sim-yaw")
                tag(ui.button("Mount", on_click=self.mount), "sim-mount")
            with ui.row().classes("items-center"):
                self.knock_angle = _number("knock, deg", 0.3, "sim-knock-angle")
                self.knock_axis = tag(
                    ui.select(["x", "y", "z"], value="x", label="about").classes("w-24"),
                    "sim-knock-axis",
                )
                tag(ui.button("Knock", on_click=self.knock, color="amber-9"), "sim-knock")
            with ui.row().classes("items-center"):
                self.board_view = tag(
                    ui.select(
                        {-1: "none", **{k: f"pose {k}" for k in range(sr.HELD_VIEWS)}},
                        value=-1,
                        label="board held",
                    ).classes("w-36"),
                    "sim-board-view",
                )
                tag(ui.button("Hold", on_click=self.hold_board), "sim-board")
                tag(
                    ui.button("Next pose", on_click=self.next_board).props("flat"),
                    "sim-board-next",
                )
                tag(
                    ui.button("Put down", on_click=self.put_board_down).props("flat"),
                    "sim-board-down",
                )

    def _build_laser(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Laser").classes("text-lg")
            with ui.row().classes("items-center"):
                self.laser_on = tag(ui.checkbox("on", value=True), "sim-laser-on")
                self.laser_roll = _number("roll, deg", 0.0, "sim-laser-roll")
                self.laser_pitch = _number("pitch, deg", 0.0, "sim-laser-pitch")
                self.laser_distance = _number("distance, mm", 800.0, "sim-laser-distance")
                tag(ui.button("Set", on_click=self.set_laser), "sim-laser")

    def _build_target(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Calibration target").classes("text-lg")
            with ui.row().classes("items-center"):
                self.target_on = tag(ui.checkbox("in the cell", value=True), "sim-target-on")
                self.target_kind = tag(
                    ui.select(list(sr.SIM_TARGETS), value="two-sided", label="kind").classes(
                        "w-32"
                    ),
                    "sim-target-kind",
                )
                self.target_x = _number("x, mm", 0.0, "sim-target-x")
                self.target_y = _number("y, mm", 650.0, "sim-target-y")
                self.target_yaw = _number("yaw, deg", 0.0, "sim-target-yaw")
                tag(ui.button("Set", on_click=self.set_target), "sim-target")

    def _build_cubes(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Cubes").classes("text-lg")
            with ui.row().classes("items-center"):
                self.cube_index = _number("cube", 0, "sim-cube-index", "w-16")
                self.cube_color = tag(
                    ui.select(list(COLOURS), value="red", label="colour").classes("w-28"),
                    "sim-cube-color",
                )
                self.cube_x = _number("x, mm", 0.0, "sim-cube-x")
                self.cube_y = _number("y, mm", 900.0, "sim-cube-y")
                self.cube_yaw = _number("yaw, deg", 0.0, "sim-cube-yaw")
            with ui.row().classes("items-center"):
                tag(ui.button("Move", on_click=lambda: self.cube("move")), "sim-cube-move")
                tag(ui.button("Add", on_click=lambda: self.cube("add")), "sim-cube-add")
                tag(ui.button("Remove", on_click=lambda: self.cube("remove")), "sim-cube-remove")

    def _build_arm(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Arm (from the pendant)").classes("text-lg")
            with ui.row().classes("items-center"):
                self.joints = [_number(f"q{i + 1}", 0.0, f"sim-q{i + 1}", "w-16") for i in range(6)]
            with ui.row().classes("items-center"):
                tag(ui.button("Read joints", on_click=self.read_joints).props("flat"), "sim-read")
                tag(ui.button("Move joints", on_click=self.move_joints), "sim-joints")
            with ui.row().classes("items-center"):
                self.xyz = [
                    _number(f"{a}, mm (base)", v, f"sim-{a}")
                    for a, v in (("x", -300.0), ("y", -350.0), ("z", 300.0))
                ]
                tag(ui.button("Move to", on_click=self.move_to), "sim-move-to")
            with ui.row().classes("items-center"):
                tag(ui.button("Close gripper", on_click=lambda: self.gripper(True)), "sim-close")
                tag(ui.button("Open gripper", on_click=lambda: self.gripper(False)), "sim-open")

    def _build_render(self) -> None:
        with ui.card().classes("w-full"):
            ui.label("Pictures with their truth").classes("text-lg")
            with ui.row().classes("items-center"):
                self.folder = tag(ui.input("folder").classes("w-64"), "sim-folder")
                tag(ui.button("Render", on_click=self.render), "sim-render")
                tag(
                    ui.button("Render the board's poses", on_click=self.render_views).props("flat"),
                    "sim-render-views",
                )

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
        if self._ticks % 4 == 1 and not self._busy:
            truth = await self._control(sr.TruthRequest(), quiet=True)
            if truth is not None:
                self._show_truth(truth)

    def _show_truth(self, truth: dict[str, Any]) -> None:
        if not self._filled:
            self._fill(truth)
        self.truth.text = "\n".join(truth_lines(truth))
        rows = cube_rows(truth)
        if rows != self.cubes.rows:
            self.cubes.rows = rows
            self.cubes.update()

    def _fill(self, truth: dict[str, Any]) -> None:
        """The forms set to the virtual cell as it is: the camera's mounting, the laser, the
        joints (so a first Set or Move changes only what the person changes)."""
        self._filled = True
        cam, laser = truth.get("camera_rotation") or {}, truth.get("laser_plane") or {}
        for field, value in (
            (self.roll, cam.get("roll_deg")),
            (self.pitch, cam.get("pitch_deg")),
            (self.yaw, cam.get("yaw_deg")),
            (self.laser_roll, laser.get("roll_deg")),
            (self.laser_pitch, laser.get("pitch_deg")),
            (self.laser_distance, laser.get("distance_mm")),
            *zip(self.joints, truth.get("joints_deg") or [], strict=False),
        ):
            if value is not None:
                field.value = f"{round(float(value), 3):g}"
        self.laser_on.value = bool(truth.get("laser_on"))
        target = truth.get("target")
        self.target_on.value = target is not None
        if target is not None:
            self.target_kind.value = target["kind"]
            x, y = target["center_mm"]
            self.target_x.value, self.target_y.value = f"{x:g}", f"{y:g}"
            self.target_yaw.value = f"{target['yaw_deg']:g}"

    # -- acting ---------------------------------------------------------------------------

    async def _control(self, request: Any, quiet: bool = False) -> dict[str, Any] | None:
        """The control-channel command of a request record (`SimLink.send`); its result, or
        None with why in the note."""
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

    async def _problems(self, cmd: str, args: dict[str, Any]) -> list[str]:
        """What the channel's schema of `cmd` (its `describe`, asked once) finds wrong with
        `args`, each naming its field."""
        if not self._schemas:
            described = await self._control(sr.DescribeRequest())
            if described is None:
                return ["the control channel did not describe its commands"]
            self._schemas = {k: v["args"] for k, v in described["commands"].items()}
        return problems(self._schemas[cmd], args)

    async def _act(
        self, request: type[Any], done: str, args: dict[str, Any], moves: str | None = None
    ) -> dict[str, Any] | None:
        """A signed-in operator's command, named by its request record's class: checked
        against the channel's schema (nothing sent when it refuses, each problem naming its
        field), confirmed when it `moves` the arm (the question), sent as the record, then the
        note and the truth after it. `args`: what was typed (None: not given)."""
        cmd = sr.command_of(request)
        if self.token() is None:
            self.note.text = f"{cmd}: sign in as operator first: nothing was sent"
            return None
        given = {k: v for k, v in args.items() if v is not None}
        found = await self._problems(cmd, given)
        if found:
            self.note.text = f"{cmd}: not sent: " + "; ".join(found)
            return None
        if moves is not None and not await confirm(f"{moves}? The simulated arm will move."):
            self.note.text = "cancelled: nothing was sent"
            return None
        self.note.text = f"{cmd} ..."
        result = await self._control(build(request, given))
        if result is None:
            return None
        shown = "" if result.get("shown", True) else " (no picture shows it yet)"
        self.note.text = done.format(**{**given, **result}) + shown
        truth = await self._control(sr.TruthRequest(), quiet=True)
        if truth is not None:
            self._show_truth(truth)
        return result

    async def mount(self) -> None:
        args = {
            "roll_deg": typed_number(self.roll.value),
            "pitch_deg": typed_number(self.pitch.value),
            "yaw_deg": typed_number(self.yaw.value),
        }
        await self._act(
            sr.CameraRequest,
            "camera mounted at roll {roll_deg:g}, pitch {pitch_deg:g}, yaw {yaw_deg:g} deg",
            args,
        )

    async def knock(self) -> None:
        args = {"angle_deg": typed_number(self.knock_angle.value), "axis": self.knock_axis.value}
        await self._act(sr.KnockRequest, "camera knocked by {angle_deg:g} deg about {axis}", args)

    async def hold_board(self) -> None:
        view = int(self.board_view.value)
        await self._act(
            sr.BoardRequest,
            "board put down" if view < 0 else f"board held at pose {view}",
            {"view": None if view < 0 else view},
        )

    async def next_board(self) -> None:
        """The board moved on to its next pose, as a person walks it through the field; after
        the last, the first again (said in the note)."""
        view = (int(self.board_view.value) + 1) % sr.HELD_VIEWS
        wrapped = view == 0 and int(self.board_view.value) == sr.HELD_VIEWS - 1
        self.board_view.value = view
        await self.hold_board()
        if wrapped:
            self.note.text += f" (all {sr.HELD_VIEWS} poses shown: the first again)"

    async def put_board_down(self) -> None:
        self.board_view.value = -1
        await self.hold_board()

    async def set_laser(self) -> None:
        args = {
            "on": bool(self.laser_on.value),
            "roll_deg": typed_number(self.laser_roll.value),
            "pitch_deg": typed_number(self.laser_pitch.value),
            "distance_mm": typed_number(self.laser_distance.value),
        }
        state = "on" if args["on"] else "off"
        await self._act(
            sr.LaserRequest,
            f"laser {state} at roll {{roll_deg:g}}, pitch {{pitch_deg:g}} deg, "
            "{distance_mm:g} mm",
            args,
        )

    async def set_target(self) -> None:
        if not self.target_on.value:
            await self._act(sr.TargetRequest, "target taken away", {"on": False})
            return
        args = {
            "kind": self.target_kind.value,
            "x_mm": typed_number(self.target_x.value),
            "y_mm": typed_number(self.target_y.value),
            "yaw_deg": typed_number(self.target_yaw.value),
        }
        await self._act(sr.TargetRequest, "target {kind} set", args)

    async def cube(self, action: str) -> None:
        args: dict[str, Any] = {"action": action}
        if action != "add":
            args["index"] = typed_number(self.cube_index.value, integer=True)
        if action != "remove":
            args["x_mm"] = typed_number(self.cube_x.value)
            args["y_mm"] = typed_number(self.cube_y.value)
            args["yaw_deg"] = typed_number(self.cube_yaw.value)
        if action == "add":
            args["color"] = self.cube_color.value
        await self._act(sr.CubeRequest, f"cube {action}: done, cube {{index}}", args)

    async def read_joints(self) -> None:
        truth = await self._control(sr.TruthRequest())
        if truth is not None:
            for field, q in zip(self.joints, truth["joints_deg"], strict=True):
                field.value = f"{float(q):.2f}"
            self._show_truth(truth)

    async def move_joints(self) -> None:
        args = {"q_deg": [typed_number(f.value) for f in self.joints]}
        done = "arm at the joints asked ({seconds:.1f} s)"
        await self._act(sr.JointsRequest, done, args, "Move the arm to these joints")

    async def move_to(self) -> None:
        args = {
            k: typed_number(f.value)
            for k, f in zip(("x_mm", "y_mm", "z_mm"), self.xyz, strict=True)
        }
        done = "tool at the point asked ({seconds:.1f} s)"
        await self._act(sr.MoveToRequest, done, args, "Move the tool to this point")

    async def gripper(self, closed: bool) -> None:
        await self._act(
            sr.GripperRequest,
            "gripper closed, holding: {holding}" if closed else "gripper open",
            {"closed": closed},
            "Close the gripper" if closed else "Open the gripper",
        )

    async def render(self) -> None:
        await self._act(
            sr.RenderRequest, "written: {images}", {"folder": self.folder.value or None}
        )

    async def render_views(self) -> None:
        folder = self.folder.value or None
        await self._act(sr.RenderRequest, "written: {images}", {"folder": folder, "views": True})
