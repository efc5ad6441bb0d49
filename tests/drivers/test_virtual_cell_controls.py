"""The simulator's controls on the virtual cell's control channel (`control.COMMANDS`): the
laser turned and moved, cubes moved, added and taken away, the arm jogged by joints and by XYZ
through the core's inverse kinematics, the gripper, and pictures rendered with their truth.
Each is checked against the truth the renderer process reports and the picture the camera
streams, so the renderer follows what the main world was told."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from jsonschema import Draft202012Validator

from omnisort_hw.core.frames import laser_normal
from omnisort_hw.sim_replies import SimDescription, SimTruth
from omnisort_hw.sim_requests import SIM_COMMANDS
from omnisort_hw.ui.sim_panel import cube_rows, truth_lines
from omnisort_hw.wire_records import from_wire, to_wire
from sim_backend.virtual_cell.launcher import VirtualCellError
from tests.sim.virtual_cell_fixture import streamed_frame, virtual_cell

pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]
WIDTH = 256


@pytest.fixture(scope="module")
def vc():
    with virtual_cell(width=WIDTH) as cell:
        yield cell


def colour_at(image: np.ndarray, pts_px: np.ndarray, channel: int) -> float:
    """Mean lead of BGR `channel` over the larger other one, in the image at pixels (N, 2):
    redness (2) on a laser line, blueness (0) on a marker."""
    h, w = image.shape[:2]
    x = np.clip(np.round(pts_px[:, 0]).astype(int), 0, w - 1)
    y = np.clip(np.round(pts_px[:, 1]).astype(int), 0, h - 1)
    px = image[y, x].astype(float)
    others = np.delete(px, channel, axis=1)
    return float(np.mean(px[:, channel] - others.max(axis=1)))


def stripe_at(image: np.ndarray, polylines_px: list[dict]) -> float:
    """Redness of the image on a truth's laser lines."""
    return colour_at(image, np.vstack([np.asarray(p["points_px"], float) for p in polylines_px]), 2)


def blue_at(image: np.ndarray, markers_px: list[dict]) -> float:
    """Blueness of the image at a truth's visible markers' centres."""
    return colour_at(image, np.array([m["center_px"] for m in markers_px if m["visible"]]), 0)


def rendered(vc, tmp: Path, name: str) -> tuple[np.ndarray, dict]:
    """A picture and the renderer's truth, through the `render` control."""
    out = vc.control("render", timeout_s=120.0, folder=str(tmp), name=name)
    assert out["images"] == [str(tmp / f"{name}.png")]
    truth = json.loads((tmp / f"{name}.truth.json").read_text())
    return cv2.imread(str(tmp / f"{name}.png")), truth


def test_the_laser_turned_and_moved_is_rendered_there(vc, tmp_path: Path) -> None:
    _, before = rendered(vc, tmp_path, "before")
    reply = vc.control(
        "laser", timeout_s=60.0, on=True, roll_deg=4.0, pitch_deg=-6.0, distance_mm=700.0
    )
    image, after = rendered(vc, tmp_path, "after")
    streamed = streamed_frame(vc.host)
    vc.control("laser", timeout_s=60.0, roll_deg=0.0, pitch_deg=0.0, distance_mm=800.0)
    assert reply["shown"]
    # The main world's truth and the renderer's: the plane asked, exactly.
    for truth in (reply, after):
        plane = truth["laser_plane"]
        assert plane["distance_mm"] == 700.0
        assert np.allclose(plane["normal"], laser_normal(*np.radians([4.0, -6.0])), atol=1e-12)
    # The stripe is where the new plane meets the scene, not where the old one did.
    lit_new = stripe_at(streamed, after["laser_polylines_px"])
    lit_old = stripe_at(streamed, before["laser_polylines_px"])
    assert lit_new > 3 * max(lit_old, 5.0), (lit_new, lit_old)
    assert np.abs(image.astype(int) - streamed).max() <= 1  # the stream shows that picture
    with pytest.raises(VirtualCellError, match="distance_mm"):
        vc.control("laser", distance_mm=10.0)


def test_cubes_moved_added_and_taken_away(vc, tmp_path: Path) -> None:
    start = vc.truth()["cubes"]
    moved = vc.control(
        "cube", timeout_s=60.0, action="move", index=0, x_mm=0.0, y_mm=560.0, yaw_deg=30.0
    )
    added = vc.control("cube", timeout_s=60.0, action="add", color="blue", x_mm=-650.0, y_mm=900.0)
    _, truth = rendered(vc, tmp_path, "cubes")
    removed = vc.control("cube", timeout_s=60.0, action="remove", index=added["index"])
    refusals = []
    for bad, field in (
        ({"action": "move", "index": 1, "x_mm": 0.0, "y_mm": 560.0}, "on cube 0"),
        ({"action": "move", "index": 1, "x_mm": 2900.0, "y_mm": 0.0}, "work area"),
        ({"action": "move", "index": 1, "x_mm": 5000.0, "y_mm": 0.0}, "'x_mm' must be a finite"),
        ({"action": "add", "color": "mauve", "x_mm": 0.0, "y_mm": 0.0}, "'color' must be one"),
        ({"action": "add", "x_mm": 0.0, "y_mm": 0.0}, "action=add needs color"),
        ({"action": "remove", "index": 9}, "index must be"),
        ({"action": "spin"}, "'action' must be one of move, add, remove"),
    ):
        with pytest.raises(VirtualCellError, match=field):
            vc.control("cube", **bad)
        refusals.append(field)
    vc.control(
        "cube",
        timeout_s=60.0,
        action="move",
        index=0,
        x_mm=start[0]["center_S_mm"][0],
        y_mm=start[0]["center_S_mm"][1],
        yaw_deg=15.0,
    )
    assert moved["shown"] and added["shown"] and removed["shown"]
    # Put down on the floor where asked: the centre half a cube above it. A cube resting on
    # the floor sinks into it by the contact's slop, which pybullet's solver keeps under
    # 0.07 mm (measured over 600 steps after a put-down at three spots); so 0.2 mm.
    floor_z = truth["floor_z_mm"]
    c0 = np.asarray(moved["cubes"][0]["center_S_mm"])
    assert np.allclose(c0[:2], [0.0, 560.0], atol=0.05), c0
    assert abs(c0[2] - (floor_z + 50.0)) < 0.2, c0
    assert len(added["cubes"]) == len(start) + 1 and added["cubes"][-1]["color"] == "blue"
    # The renderer's world has the same cubes: the moved one, and the one added.
    new = truth["cubes"][-1]
    assert len(truth["cubes"]) == len(start) + 1 and new["colour"] == "blue"
    assert np.allclose(new["center_S_mm"][:2], [-650.0, 900.0], atol=0.05), new
    assert np.allclose(truth["cubes"][0]["center_S_mm"], c0, atol=0.2)
    assert abs(truth["cubes"][0]["yaw_deg"] - 30.0) < 0.2
    assert len(removed["cubes"]) == len(start)


def test_the_arm_jogged_by_joints_and_by_xyz_and_the_gripper(vc) -> None:
    home = vc.truth()["joints_deg"]
    target = [float(q) for q in np.add(home, [10.0, -5.0, 5.0, 0.0, 0.0, 0.0])]
    by_joints = vc.control("joints", timeout_s=120.0, q_deg=target)
    at_joints = vc.truth()
    by_xyz = vc.control("move_to", timeout_s=120.0, x_mm=-300.0, y_mm=-350.0, z_mm=300.0)
    at_xyz = vc.truth()
    with pytest.raises(VirtualCellError, match="out of reach"):
        vc.control("move_to", x_mm=1900.0, y_mm=0.0, z_mm=0.0)
    with pytest.raises(VirtualCellError, match="'q_deg' must be an array of 6"):
        vc.control("joints", q_deg=[0.0] * 5)
    closed = vc.control("gripper", timeout_s=30.0, closed=True)
    gripping = vc.truth()
    vc.control("gripper", timeout_s=30.0, closed=False)
    vc.control("joints", timeout_s=120.0, q_deg=home)
    # Moves end exactly on their targets (the planner's last sample is the target), and the
    # simulated world's arm stands there.
    assert by_joints["shown"] and by_xyz["shown"]
    assert np.allclose(at_joints["joints_deg"], target, atol=1e-9)
    assert np.allclose(at_xyz["tcp_B_mm"], [-300.0, -350.0, 300.0], atol=1e-6), at_xyz["tcp_B_mm"]
    assert closed["closed"] and gripping["gripper_closed"] and not gripping["held"]


def test_the_channel_describes_its_commands_as_json_schema(vc) -> None:
    raw = vc.control("describe")
    described = from_wire(SimDescription, raw).commands  # the record holds it all
    assert to_wire(from_wire(SimDescription, raw)) == raw
    assert set(described) == set(SIM_COMMANDS)
    for spec in described.values():
        Draft202012Validator.check_schema(spec.args)
    with pytest.raises(VirtualCellError, match="'angle_deg' must be a finite number within"):
        vc.control("knock", angle_deg=1000.0)


def test_the_target_taken_away_moved_and_changed(vc, tmp_path: Path) -> None:
    _, before = rendered(vc, tmp_path, "target_before")
    away = vc.control("target", timeout_s=60.0, on=False)
    _, gone = rendered(vc, tmp_path, "target_away")
    moved = vc.control("target", timeout_s=60.0, x_mm=40.0, y_mm=680.0, yaw_deg=3.0)
    image, after = rendered(vc, tmp_path, "target_moved")
    three = vc.control("target", timeout_s=60.0, kind="three-sided")
    with pytest.raises(VirtualCellError, match="target"):
        vc.control("target", kind="round")
    with pytest.raises(VirtualCellError, match="needs y_mm"):
        vc.control("target", x_mm=10.0)
    back = vc.control("target", timeout_s=60.0, kind="two-sided", x_mm=0.0, y_mm=650.0, yaw_deg=0.0)
    assert away["target"] is None and gone["target"] is None and gone["markers_px"] == []
    # The renderer's truth: the pose asked, its walls and markers there.
    assert after["target"]["center_mm"] == [40.0, 680.0] and after["target"]["yaw_deg"] == 3.0
    assert moved["target"]["center_mm"] == [40.0, 680.0]
    assert len(after["markers_px"]) == 8 and len(after["target"]["walls"]) == 2
    # The picture shows the markers where the moved target has them, not where they were.
    assert blue_at(image, after["markers_px"]) > 3 * max(blue_at(image, before["markers_px"]), 5)
    assert three["target"]["kind"] == "three-sided"
    assert back["target"] == {"kind": "two-sided", "center_mm": [0.0, 650.0], "yaw_deg": 0.0}


def test_the_truth_reads_as_the_simulator_tabs_records(vc) -> None:
    """`truth` as the Simulator tab reads it (`from_wire(SimTruth, ...)`): every field the wire
    holds, the lines and cube rows the tab shows from them, and the target taken away."""
    raw = vc.control("truth")
    truth = from_wire(SimTruth, raw)
    cam = raw["camera_rotation"]
    assert (truth.camera.roll_deg, truth.camera.pitch_deg, truth.camera.yaw_deg) == (
        cam["roll_deg"],
        cam["pitch_deg"],
        cam["yaw_deg"],
    )
    assert truth.laser.distance_mm == raw["laser_plane"]["distance_mm"]
    assert truth.laser_on is raw["laser_on"]
    assert list(truth.joints_deg) == raw["joints_deg"] and len(truth.joints_deg) == 6
    assert list(truth.tcp_B_mm) == raw["tcp_B_mm"]
    assert [(c.index, c.color, list(c.center_S_mm)) for c in truth.cubes] == [
        (c["index"], c["color"], c["center_S_mm"]) for c in raw["cubes"]
    ]
    assert truth.target is not None and list(truth.target.center_mm) == raw["target"]["center_mm"]
    lines = truth_lines(truth)
    assert lines[0] == (
        f"camera: roll {cam['roll_deg']:.3f}, pitch {cam['pitch_deg']:.3f}, "
        f"yaw {cam['yaw_deg']:.3f} deg"
    )
    assert [r["index"] for r in cube_rows(truth)] == [c["index"] for c in raw["cubes"]]
    vc.control("target", timeout_s=60.0, on=False)
    try:
        away = from_wire(SimTruth, vc.control("truth"))
        assert away.target is None and "target: away" in truth_lines(away)
    finally:
        vc.control("target", timeout_s=60.0, kind="two-sided", x_mm=0.0, y_mm=650.0, yaw_deg=0.0)
