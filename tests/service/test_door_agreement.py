"""One reply through every door: each command that has a CLI door gives, on the same input, the
same reply from `omnisort ... --json` as from the running service over the protocol, times
excepted. Every other command of the schema is named below with why it has no CLI door, so a
new command has to take a side.

The cell is the simulated sorting cell with its true calibration; the service runs in this
process (`start_in_thread`), the CLI in a subprocess on the same cell file. The images both
doors get are the service's own captures. The commands that write a calibration run last
(an extrinsic calibration drops the robot base the others need).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import pytest

pytest.importorskip("pybullet", reason="the cell is the simulated one")

from omnisort_hw.cell.cell import Cell
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.pipeline import replies
from omnisort_hw.service.client import Client
from omnisort_hw.service.demo import calibrate_from_truth, write_config
from omnisort_hw.service.protocol import COMMANDS, encode
from omnisort_hw.service.server import RunningService, Service, start_in_thread
from omnisort_hw.wire_records import from_wire, to_wire
from tests.cli_json import cli_result

pytestmark = pytest.mark.timeout(900)

WIDTH = 640
VIEWS = 6
TIME_KEYS = {"checked_at", "created", "cycle"}
"""When a reply was made and how long it took (a sort's measured cycle, and every measured
duration `*_s` but the planned ones): never the same twice."""
PLACE_KEYS = {"overlay_png", "report", "uncertainty_png"}
"""Files each door writes in its own place (the service beside its store, the CLI beside the
files it was given); both must exist. An image kept (a capture) is compared by its sha256."""
DOOR_KEYS = {"camera_serial"}
"""What only the service knows: the serial of the camera attached to the cell."""
TRUTH_KEYS = {
    "in_right_bin",
    "error_mm",
    "sorted_ok",
    "mean_position_error_mm",
    "collisions",
    "collision_events",
    "errors_B_mm",
}
TRUTH_CHECK = "cubes not in their bin"
"""What only the CLI sees on the simulated cell: it holds the simulated world, whose truth
checks each cube against its bin (the service never learns that its cell is simulated). The
truth must pass, so the verdicts' levels still agree."""

SERVICE_ONLY = {
    "status": "the service's own state",
    "describe": "the protocol's schema",
    "capture": "the cell's camera, held by the service",
    "view": "a live picture for a client's screen (the CLI's pictures are files)",
    "detect": "a live frame's pattern for a screen placing it (each calibration detects its own)",
    "views": "the cell's camera's views kept in its store (the CLI calibrates from any folder)",
    "history": "the service's calibration store (the CLI's files are wherever it was told)",
    "geometry": "the cell in 3D for a client's screen, from the service's store and its arm",
    "picture": "a picture the service wrote, for a client elsewhere (the CLI's are files)",
    "laser": "the cell's laser, held by the service",
    "move": "the arm, held by the service",
    "acknowledge_drift": "the watchdog's state",
    "adopt": "the CLI's files taken into the service's store (the CLI writes them directly)",
    "stop": "the running job",
    "estop": "the running job and the devices",
    "reset": "the service's fault state",
    "shutdown": "the service itself",
}


@dataclass
class Doors:
    tmp: Path
    config: Path
    state: Path
    running: RunningService
    client: Client
    laser_off: str
    laser_on: str
    views: Path
    target: str  # a rendered two-sided target (no cubes in front of its markers)


def _capture(client: Client, laser: bool) -> str:
    reply = client.call("capture", {"laser": laser})
    assert reply["ok"], reply
    return str(reply["result"]["path"])


@pytest.fixture(scope="module")
def doors(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Doors]:
    from sim_backend.dataset import checkerboard_views
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene

    tmp = tmp_path_factory.mktemp("doors")
    config = write_config(tmp, WIDTH)
    calibrate_from_truth(config)
    checkerboard_views(tmp / "views", n=VIEWS, seed=1, width=WIDTH, progress=False)
    target, _ = render_scene(sized(load_scene("two_sided"), WIDTH), seed=7)
    cv2.imwrite(str(tmp / "target.png"), target)
    cell = Cell.from_settings(load_cell_config(config))
    cell.connect()
    running = start_in_thread(Service(cell, ServiceConfig(port=0)))
    client = Client(running.host, running.port, timeout_s=600)
    try:
        off, on = _capture(client, False), _capture(client, True)
        assert client.call("laser", {"on": False})["ok"]
        views, target_png = tmp / "views", str(tmp / "target.png")
        yield Doors(tmp, config, tmp / "state", running, client, off, on, views, target_png)
    finally:
        client.close()
        running.stop()


def _normalised(obj: Any) -> Any:
    """`obj` without its times, and each door's own places checked and left out."""
    if isinstance(obj, dict) and {"path", "sha256"} <= set(obj):  # an image each door keeps
        assert Path(obj["path"]).is_file(), obj
        obj = {k: v for k, v in obj.items() if k != "path"}
    if isinstance(obj, dict):
        out = {}
        for key, value in obj.items():
            measured = key.endswith("_s") and not key.startswith("planned")
            if measured or key in TIME_KEYS or key in DOOR_KEYS or key in TRUTH_KEYS:
                continue
            if key == "checks" and isinstance(value, list):
                value = [
                    _unchanged_cubes(c) if "covered" in c else c
                    for c in value
                    if c.get("name") != TRUTH_CHECK
                ]
            if key in PLACE_KEYS:
                assert value is None or Path(value).is_file(), (key, value)
                continue
            out[key] = _normalised(value)
        return out
    if isinstance(obj, list):
        return [_normalised(v) for v in obj]
    return obj


def _unchanged_cubes(check: dict[str, Any]) -> dict[str, Any]:
    """A change check between picks as both doors must agree on it. Its frame is taken while
    the arm carries the cube (`pipeline.scene_check`), so where the arm stands in it, and so
    which boxes it covers (`hidden` rather than `still`) and how much of each box shows
    (`covered`), depends on the threads' timing: only what changed is the same at every door."""
    same = {k: v for k, v in check.items() if k not in ("still", "hidden", "covered")}
    return same | {"unchanged": sorted([*check["still"], *check["hidden"]])}


Case = Callable[[Doors], tuple[dict[str, Any], list[str], tuple[int, ...]]]
"""A door pair: (the service's args, the CLI's arguments, the CLI's accepted exit codes)."""


def _system(d: Doors) -> list[str]:
    return ["--system", str(d.state / "system.json"), "--config", str(d.config)]


CASES: dict[str, tuple[str, Case]] = {
    "map": (
        "map",
        lambda d: (
            {"image": d.laser_on, "points": True, "picture": True},
            ["map", d.laser_on, "--points", *_system(d)],
            (0,),
        ),
    ),
    "locate": (
        "locate",
        lambda d: (
            {"image": d.laser_off, "laser_image": d.laser_on, "colors": ["red", "blue"]},
            [
                "locate",
                d.laser_off,
                "--laser-image",
                d.laser_on,
                "--colors",
                "red,blue",
                *_system(d),
            ],
            (0,),
        ),
    ),
    "register_robot": (
        "register_robot",
        lambda d: (
            {"image": d.laser_off, "save": False, "model": "UR5e"},
            ["register-robot", d.laser_off, "--no-save", "--model", "UR5e", *_system(d)],
            (0,),
        ),
    ),
    "check": (
        "check",
        lambda d: ({"image": d.laser_off}, ["check", d.laser_off, *_system(d)], (0, 4)),
    ),
    "sort": (
        "sort",
        lambda d: (
            {"max_objects": 1},
            ["sort", "--max", "1", "--config", str(d.config)],
            (0,),
        ),
    ),
    "calibrate intrinsics": (
        "calibrate",
        lambda d: (
            {"what": "intrinsics", "folder": str(d.views), "square_mm": 116.0},
            [
                "intrinsics",
                "calibrate",
                *sorted(str(p) for p in d.views.glob("*.png")),
                "--square",
                "116",
                "--out",
                str(d.tmp / "cli" / "camera.json"),
            ],
            (0,),
        ),
    ),
    "calibrate extrinsics": (
        "calibrate",
        lambda d: (
            {"what": "extrinsics", "image": d.target, "target": "two-sided"},
            [
                "extrinsics",
                "calibrate",
                d.target,
                "--target",
                "two-sided",
                "--camera",
                str(d.state / "camera.json"),
                "--config",
                str(d.config),
                "--out",
                str(d.tmp / "cli" / "system.json"),
            ],
            (0,),
        ),
    ),
}


REPLY_TYPES: dict[str, Any] = {
    "map": replies.MapReply,
    "locate": replies.LocateReply,
    "register_robot": replies.RegisterReply,
    "check": replies.DriftReply,
    "sort": replies.SortReply,
    "calibrate extrinsics": replies.ExtrinsicsReply,
    "calibrate intrinsics": replies.IntrinsicsReply,
}
"""The declared reply record of each use case (`pipeline.replies`), held against the real
one."""


def test_every_command_has_a_door_pair_or_a_reason() -> None:
    paired = {cmd for cmd, _ in CASES.values()}
    assert paired.isdisjoint(SERVICE_ONLY)
    assert paired | set(SERVICE_ONLY) == set(COMMANDS)


@pytest.mark.parametrize("case", list(CASES))
def test_the_cli_and_the_service_give_one_reply(doors: Doors, case: str) -> None:
    cmd, make = CASES[case]
    args, cli_args, ok_codes = make(doors)
    (doors.tmp / "cli").mkdir(exist_ok=True)
    cli = dict(cli_result(*cli_args, ok_codes=ok_codes))
    reply = doors.client.call(cmd, args)
    assert reply["ok"], reply
    service = json.loads(json.dumps(reply["result"]))
    if "path" in service and service["path"] is not None:  # each door's file, the same name
        assert Path(service.pop("path")).name == Path(cli.pop("path")).name
    assert _normalised(cli) == _normalised(service)
    declared = REPLY_TYPES.get(case)
    if declared is not None:  # the reply is its record, whole: no key lost, none made up
        read = to_wire(from_wire(declared, reply["result"]))
        assert json.loads(encode(read)) == reply["result"], case  # NaN sent as null, again
    # Not a vacuous agreement: each door measured something it judged usable.
    assert service["verdict"]["level"] != "fail", service["verdict"]
