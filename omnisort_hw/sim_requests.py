"""The virtual cell's control channel's commands, declared as the service's are
(`request_fields`): one request record per command, each argument once with its type,
unit, bounds, choices and help. From it the channel checks every request (`validate`), its
`describe` gives each command's JSON Schema, `SimLink.execute` sends a command's record, and
the Simulator tab checks its forms against the schema. Nothing of the simulator is imported: the
client and the channel share this contract.

Bounds are the simulator's own (a mounting within +-180 deg, the laser's emitter within
+-60 deg and 50..3000 mm, as `sim_backend.sim_cell` enforces them), and a knock's is what a
knock is: a bump turns a camera by a fraction of a degree to a few degrees on its mount;
beyond KNOCK_MAX_DEG it has come off its mount, which is a new mounting (`camera`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from omnisort_hw.request_fields import (
    GIVEN,
    ArgumentError,
    build,
    check_args,
    param,
    schema_of,
    summary_line,
)
from omnisort_hw.sim_replies import (
    Record,
    SimArmStood,
    SimBoardHeld,
    SimCameraTurned,
    SimCommandDescription,
    SimCubesSet,
    SimDescription,
    SimDone,
    SimDropped,
    SimGripperSet,
    SimLaserSet,
    SimRendered,
    SimTargetSet,
    SimTruth,
)

HELD_VIEWS = 12
"""The held board's poses covering the field (the intrinsics' views), 0..HELD_VIEWS-1."""
KNOCK_MAX_DEG = 10.0
FACES = ("arm", "dashboard", "laser", "camera", "all")
AXES = ("x", "y", "z")
SCENE_TARGETS = {"two-sided": "two_sided", "three-sided": "three_sided"}
"""The targets the virtual cell builds (core.choices.TARGETS' wall targets), each with its
scene's name (sim_backend's scene files); the channel speaks the first."""
SIM_TARGETS = tuple(SCENE_TARGETS)
SIM_COLORS = ("red", "green", "blue", "yellow", "black", "white", "orange", "grey")
"""The colours the renderer paints a cube (sim_backend.scene.NAMED_COLORS)."""
FLOOR_MM = 3000.0  # a place on the floor of S, within the simulated cell's room
ARM_REACH_MM = 2000.0  # a point of the robot base's frame, beyond any UR's reach

_FACE_HELP = "arm, dashboard, laser, camera or all"
_MOVE_OR_ADD = (("action", ("move", "add")),)
_MOVE_OR_REMOVE = (("action", ("move", "remove")),)


def _floor(help: str, *, when: Any = (), needed: Any = ()) -> Any:
    return param(
        None,
        unit="mm",
        lo=-FLOOR_MM,
        hi=FLOOR_MM,
        help=help,
        only_when=when,
        required_when=needed,
    )


def _yaw(help: str, *, when: Any = ()) -> Any:
    return param(None, unit="deg", lo=-180.0, hi=180.0, help=help, only_when=when)


@dataclass(frozen=True)
class NoArgs:
    """A command without arguments."""


@dataclass(frozen=True)
class TruthRequest:
    """The renderer's truth: cube poses in S, the bin each is in, collisions, the camera's
    rotation and the laser plane as system.json holds them, the joints and the gripper."""


@dataclass(frozen=True)
class DescribeRequest:
    """Each command and the JSON Schema of its arguments."""


@dataclass(frozen=True)
class DropRequest:
    """A face's connections closed, as a cable pulled."""

    what: str = param("arm", choices=FACES, help=_FACE_HELP)


@dataclass(frozen=True)
class StallRequest:
    """A face stops answering for a while."""

    what: str = param("arm", choices=FACES, help=_FACE_HELP)
    seconds: float = param(3600.0, unit="s", lo=0.0, hi=86400.0, help="how long")


@dataclass(frozen=True)
class UnstallRequest:
    """A stalled face answers again."""

    what: str = param("arm", choices=FACES, help=_FACE_HELP)


@dataclass(frozen=True)
class BoardRequest:
    """A checkerboard held in front of the camera at one of the poses covering the field, or
    put down (no view)."""

    view: int | None = param(
        None, lo=0, hi=HELD_VIEWS - 1, help="the held pose; none: the board put down"
    )


@dataclass(frozen=True)
class CameraRequest:
    """The camera mounted at these angles (docs/frames.md's roll, pitch, yaw of S)."""

    roll_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, help="roll")
    pitch_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, help="pitch")
    yaw_deg: float = param(0.0, unit="deg", lo=-180.0, hi=180.0, help="yaw")


@dataclass(frozen=True)
class KnockRequest:
    """The camera turned on its mount from where it is, as a knock turns it."""

    angle_deg: float = param(0.5, unit="deg", lo=-KNOCK_MAX_DEG, hi=KNOCK_MAX_DEG, help="the turn")
    axis: str = param("x", choices=AXES, help="about this axis of S")


@dataclass(frozen=True)
class LaserRequest:
    """The emitter switched, turned and moved (each left as it is when not given)."""

    on: bool | None = param(None, help="the emitter on or off")
    roll_deg: float | None = param(None, unit="deg", lo=-60.0, hi=60.0, help="the plane's roll")
    pitch_deg: float | None = param(None, unit="deg", lo=-60.0, hi=60.0, help="the plane's pitch")
    distance_mm: float | None = param(
        None, unit="mm", lo=50.0, hi=3000.0, help="the plane's distance below the camera"
    )


@dataclass(frozen=True)
class TargetRequest:
    """The calibration target put in the cell, changed, moved, or taken away."""

    on: bool = param(True, help="in the cell (false: taken away)")
    kind: str | None = param(None, choices=SIM_TARGETS, help="the target's kind")
    x_mm: float | None = _floor("its centre on the floor, x of S", needed=(("y_mm", GIVEN),))
    y_mm: float | None = _floor("its centre on the floor, y of S", needed=(("x_mm", GIVEN),))
    yaw_deg: float | None = _yaw("its turn about the vertical")


@dataclass(frozen=True)
class CubeRequest:
    """A cube moved (put down there), added, or taken away."""

    action: str = param(choices=("move", "add", "remove"), help="what is done")
    index: int | None = param(
        None,
        lo=0,
        hi=255,
        help="the cube (its index in the truth)",
        only_when=_MOVE_OR_REMOVE,
        required_when=_MOVE_OR_REMOVE,
    )
    color: str | None = param(
        None,
        choices=SIM_COLORS,
        help="the new cube's colour",
        only_when=(("action", ("add",)),),
        required_when=(("action", ("add",)),),
    )
    x_mm: float | None = _floor("where, x of S", when=_MOVE_OR_ADD, needed=_MOVE_OR_ADD)
    y_mm: float | None = _floor("where, y of S", when=_MOVE_OR_ADD, needed=_MOVE_OR_ADD)
    yaw_deg: float | None = _yaw("its turn about the vertical", when=_MOVE_OR_ADD)


@dataclass(frozen=True)
class JointsRequest:
    """The arm jogged to these joints from the pendant; the reply comes once it stands."""

    q_deg: tuple[float, ...] = param(length=6, lo=-360.0, hi=360.0, unit="deg", help="6 joints")


@dataclass(frozen=True)
class MoveToRequest:
    """The tool moved to a point of the robot base, turned as it is, through the core's inverse
    kinematics; the reply comes once it stands."""

    x_mm: float = param(unit="mm", lo=-ARM_REACH_MM, hi=ARM_REACH_MM, help="x of B")
    y_mm: float = param(unit="mm", lo=-ARM_REACH_MM, hi=ARM_REACH_MM, help="y of B")
    z_mm: float = param(unit="mm", lo=-ARM_REACH_MM, hi=ARM_REACH_MM, help="z of B")


@dataclass(frozen=True)
class GripperRequest:
    """The gripper closed (on the cube between its fingers) or opened."""

    closed: bool = param(help="closed, or open")


@dataclass(frozen=True)
class RenderRequest:
    """The picture as it is now and the renderer's truth beside it (NAME.png,
    NAME.truth.json); with `views`, one pair per held-board pose instead (the intrinsics'
    dataset)."""

    folder: str = param(kind="path", help="where the pictures and their truth go")
    name: str | None = param(
        None,
        max_chars=64,
        help="the pair's name (letters, digits, - and _)",
        only_when=(("views", (None, False)),),
        why="is for one picture; the board's poses are named by their pose",
    )
    views: bool = param(False, help="one pair per held-board pose")


@dataclass(frozen=True)
class SimCommand:
    """A control-channel command: its name, the record that declares its arguments, the record
    of its reply (`sim_replies`), its help (default: the request's first docstring line)."""

    name: str
    request: type[Any]
    reply: Any  # a `sim_replies` record, or `Record` (the status: the controller's own keys)
    help: str = ""

    @property
    def summary(self) -> str:
        return self.help or summary_line(self.request)

    def schema(self) -> dict[str, Any]:
        """The JSON Schema (draft 2020-12) of this command's arguments."""
        return schema_of(self.request, self.name, self.summary)

    def describe(self) -> SimCommandDescription:
        return SimCommandDescription(self.summary, self.schema())


SIM_COMMANDS: dict[str, SimCommand] = {
    c.name: c
    for c in (
        SimCommand(
            "status", NoArgs, Record, "the controller's modes, the laser, renders, late ticks"
        ),
        SimCommand("truth", TruthRequest, SimTruth),
        SimCommand("describe", DescribeRequest, SimDescription),
        SimCommand(
            "protective_stop", NoArgs, SimDone, "a protective stop, as a safety sensor triggers it"
        ),
        SimCommand("emergency_stop", NoArgs, SimDone, "an emergency stop"),
        SimCommand(
            "release_emergency_stop", NoArgs, SimDone, "the emergency stop button pulled out again"
        ),
        SimCommand("drop", DropRequest, SimDropped),
        SimCommand("stall", StallRequest, SimDone),
        SimCommand("unstall", UnstallRequest, SimDone),
        SimCommand("board", BoardRequest, SimBoardHeld),
        SimCommand("camera", CameraRequest, SimCameraTurned),
        SimCommand("knock", KnockRequest, SimCameraTurned),
        SimCommand("laser", LaserRequest, SimLaserSet),
        SimCommand("target", TargetRequest, SimTargetSet),
        SimCommand("cube", CubeRequest, SimCubesSet),
        SimCommand("joints", JointsRequest, SimArmStood),
        SimCommand("move_to", MoveToRequest, SimArmStood),
        SimCommand("gripper", GripperRequest, SimGripperSet),
        SimCommand("render", RenderRequest, SimRendered),
    )
}


_COMMAND_OF = {c.request: c.name for c in SIM_COMMANDS.values() if c.request is not NoArgs}


def command_of(request: Any) -> str:
    """The command a request record (or its class) is declared for; ValueError for `NoArgs`,
    which several commands share."""
    cls = request if isinstance(request, type) else type(request)
    if cls not in _COMMAND_OF:
        raise ValueError(f"{cls.__name__} names no single control-channel command")
    return _COMMAND_OF[cls]


def describe_sim() -> SimDescription:
    """The channel's `describe`: every command with its help and its arguments' JSON Schema."""
    return SimDescription({name: c.describe() for name, c in SIM_COMMANDS.items()})


def validate(req: dict[str, Any]) -> tuple[str, Any]:
    """A control-channel request (`{"cmd": ..., args...}`) checked against its declaration:
    (command, its request record), or ValueError naming the command and the field."""
    cmd = req.get("cmd")
    spec = SIM_COMMANDS.get(cmd) if isinstance(cmd, str) else None
    if spec is None:
        raise ValueError(f"unknown command {cmd!r} (known: {', '.join(SIM_COMMANDS)})")
    raw = {k: v for k, v in req.items() if k != "cmd"}
    try:
        return spec.name, build(spec.request, check_args(spec.request, spec.name, raw))
    except ArgumentError as exc:
        raise ValueError(str(exc)) from None
