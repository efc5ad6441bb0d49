"""Change checks between picks on the simulated cell: a cube taken away by hand while the arm
picks another is never approached; a cube knocked aside is located again and sorted; a cube put
down after the first capture is found and sorted; the cubes nobody touched are not located
again. Truth (bins, contacts) from the simulator."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

import pybullet as p

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.pipeline.calibration_source import MemoryCalibration
from omnisort_hw.pipeline.scene_check import keep_fraction
from omnisort_hw.pipeline.sort import Sorter
from omnisort_hw.wire_records import to_wire
from sim_backend.sort_harness import SimVerifier, sim_registration_config, sim_sort_config
from tests.pipeline.sorting_scene import sorting_scene, spy_linear_targets


def _sort(change: str) -> dict[str, Any]:
    """Sort the shipped scene; at the first grasp, `change` ("remove", "knock" or "none") the
    truth cube farthest from the one being grasped, or ("add") put back the cube that was taken
    out of the cell before the first capture. Returns what the test checks."""
    from sim_backend.devices import SimArm, SimCamera, SimCell, SimLaserSwitch

    scene = sorting_scene()
    cell = SimCell(scene, seed=5)
    cam, laser, arm = SimCamera(cell), SimLaserSwitch(cell), SimArm(cell)
    for d in (cam, laser, arm):
        d.connect()
    try:
        cam.grab(with_truth=True)
        calib = SystemCalibration.from_json(cam.last_truth, source="truth")
        verifier = SimVerifier(arm)
        targets = spy_linear_targets(arm)
        changed: dict[str, Any] = {}
        if change == "add":  # out of the cell during the first capture, put down later
            last = max(verifier.true_cubes(), key=lambda t: float(t.center_S[1]))
            with cell.lock:
                cid = cell.world.client
                pose = p.getBasePositionAndOrientation(last.body, physicsClientId=cid)
                p.resetBasePositionAndOrientation(
                    last.body, [5.0, 5.0, pose[0][2]], pose[1], physicsClientId=cid
                )
                cell.world.version += 1

        def on_pick(phase: str, out: Any) -> None:
            if phase != "grasping" or changed or change == "none":
                return
            if change == "add":
                changed.update(color=last.color, before_S=last.center_S.copy(), body=last.body)
                with cell.lock:
                    p.resetBasePositionAndOrientation(
                        last.body, *pose, physicsClientId=cell.world.client
                    )
                    cell.world.version += 1
                return
            grasped = np.asarray(out.center_S_mm, float)
            cubes = verifier.true_cubes()
            far = max(cubes, key=lambda t: float(np.linalg.norm(t.center_S[:2] - grasped[:2])))
            changed.update(color=far.color, before_S=far.center_S.copy(), body=far.body)
            with cell.lock:
                client = cell.world.client
                pos, orn = p.getBasePositionAndOrientation(far.body, physicsClientId=client)
                if change == "remove":  # taken out of the cell by hand
                    new, quat = [5.0, 5.0, pos[2]], orn
                else:  # knocked 50 mm aside and turned by 30 degrees
                    new = [pos[0] + 0.05 * np.sign(-pos[0]), pos[1], pos[2]]
                    quat = p.getQuaternionFromEuler([0.0, 0.0, np.radians(30.0)])
                p.resetBasePositionAndOrientation(far.body, new, quat, physicsClientId=client)
                cell.world.version += 1

        verifier.start()
        sorter = Sorter(
            cam,
            arm,
            laser,
            MemoryCalibration(calib),
            sim_sort_config(scene),
            sim_registration_config(scene),
            on_pick=on_pick,
            clock=lambda: cell.world.sim_time,
        )
        report = sorter.run(register=True, on_located=verifier.on_located)
        verifier.stop()
        truth = verifier.true_cubes()
        T_SB = verifier.T_SB()
        return {
            "report": to_wire(report.reply()),  # as every door sends it
            "changed": changed,
            "bins": {t.body: verifier.bin_of(t.center_S) for t in truth},
            "colors": {t.body: t.color for t in truth},
            "collisions": list(verifier.collisions),
            "targets_S": [T_SB[:3, :3] @ t + T_SB[:3, 3] for t in targets],
            "size_mm": scene.cubes[0].size_mm,
        }
    finally:
        for d in (cam, laser, arm):
            d.close()
        cell.close()


@pytest.mark.parametrize("change", ["remove", "knock", "add"])
def test_checks_between_picks(change: str) -> None:
    res = _sort(change)
    rep, changed = res["report"], res["changed"]
    assert res["collisions"] == [], res["collisions"]
    checks = rep["checks"]
    assert checks, "no check capture was taken"
    body = changed["body"]
    others = [b for b in res["bins"] if b != body]
    assert all(res["bins"][b] == res["colors"][b] for b in others), res["bins"]
    if change == "remove":
        # the cubes nobody touched: no check sees them moved or new, and only the check
        # that found the cube gone located the image again
        assert not any(c["moved"] or c["added"] for c in checks), checks
        assert all(c["gone"] for c in checks if c["located_again"]), checks
        gone = [o for o in rep["cubes"] if o["reason"].startswith("gone")]
        assert len(gone) == 1 and gone[0]["color"] == changed["color"], rep["cubes"]
        # never approached: no straight-line target within a cube's size of where it was
        d = [np.linalg.norm(t[:2] - changed["before_S"][:2]) for t in res["targets_S"]]
        assert min(d) > res["size_mm"], min(d)
        assert sum(o["status"] == "sorted" for o in rep["cubes"]) == len(rep["cubes"]) - 1
    elif change == "add":
        assert [c["added"] for c in checks if c["added"]] == [[changed["color"]]], checks
        assert len(rep["cubes"]) == len(res["bins"]), rep["cubes"]  # every true cube, once
        assert all(o["status"] == "sorted" for o in rep["cubes"]), rep["cubes"]
        assert res["bins"][body] == changed["color"]  # the cube put down is in its bin
    else:
        moved = [o for o in rep["cubes"] if o.get("relocated")]
        assert len(moved) == 1 and moved[0]["color"] == changed["color"], rep["cubes"]
        assert moved[0]["status"] == "sorted"
        assert res["bins"][body] == changed["color"]  # the knocked cube is in its bin


def test_keep_fraction_follows_the_gripper_margin() -> None:
    """A shift of half the gripper's margin per side leaves 1 - margin / (2 size) covered:
    150 mm stroke, 100 mm cube -> 25 mm margin per side, 12.5 mm shift -> 0.875."""
    cfg = sim_sort_config(sorting_scene())
    assert cfg.cube_size_mm == 100.0 and cfg.gripper_stroke_mm == 150.0
    assert keep_fraction(cfg) == pytest.approx(1.0 - 12.5 / 100.0)
