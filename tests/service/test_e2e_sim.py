"""End to end: `omnisort serve` on the simulated cell, driven through TCP, checked against truth.

The service runs as a subprocess exactly as under systemd (READY and the port come over a
real NOTIFY_SOCKET). Every stage is checked against the simulator's truth with tolerances from
the accuracy goals at this camera's resolution, and every cube must be sorted; a stage that
answers with an error fails the test with the service's message. The test prints what ran.
"""

from __future__ import annotations

import itertools
import json
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from omnisort_hw.runlog import entity_paths
from omnisort_hw.service.client import Client
from omnisort_hw.service.launch import start_service

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

PROJECT_ROOT = Path(__file__).resolve().parents[2]
WIDTH = 960
SCENE = "sorting"

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]
# Typed errors of the core a stage may answer with (the service passes them through).
CORE_ERRORS = {"not_available", "feature_not_found", "calibration_failed", "bad_input"}


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


class _Diagnosed:
    """A client whose timeouts dump the service's thread stacks (SIGUSR1) into the failure."""

    def __init__(self, client: Client, proc: subprocess.Popen[bytes], tmp: Path) -> None:
        self.client, self.proc, self.tmp = client, proc, tmp

    def call(self, cmd: str, args: dict | None = None, **kw: Any) -> dict:
        from omnisort_hw.service.client import ClientError

        try:
            return self.client.call(cmd, args, **kw)
        except ClientError as exc:
            self.proc.send_signal(signal.SIGUSR1)
            time.sleep(1.0)
            log = (self.tmp / "serve.log").read_text()[-6000:]
            raise AssertionError(f"{cmd}: {exc}\n--- service log ---\n{log}") from None

    def __enter__(self) -> _Diagnosed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.client.close()


def _poll_status_while(port: int, action) -> tuple[dict, list[str]]:
    """Run `action` while another connection polls `status` every 50 ms."""
    seen: dict = {"states": set(), "count": 0, "progress_max": 0}
    errors: list[str] = []
    stop = threading.Event()

    def poll() -> None:
        with Client("127.0.0.1", port, timeout_s=5) as p:
            while not stop.is_set():
                try:
                    reply = p.call("status")
                except Exception as exc:
                    errors.append(repr(exc))
                    return
                if not reply["ok"]:
                    errors.append(str(reply))
                seen["states"].add(reply["result"]["state"])
                seen["count"] += 1
                job = reply["result"]["job"]
                if job is not None:
                    seen["progress_max"] = max(seen["progress_max"], len(job["progress"]))
                time.sleep(0.05)

    t = threading.Thread(target=poll, daemon=True)
    t.start()
    try:
        seen["reply"] = action()
    finally:
        stop.set()
        t.join(10)
    return seen, errors


def _polyline_samples(polylines: list[dict], step_mm: float = 2.0) -> np.ndarray:
    out = []
    for pl in polylines:
        p = np.asarray(pl["points_mm"], float)
        for a, b in itertools.pairwise(p):
            n = max(2, int(np.linalg.norm(b - a) / step_mm) + 1)
            out.append(a + np.linspace(0, 1, n)[:, None] * (b - a))
    return np.concatenate(out)


def test_whole_job_on_the_simulated_cell(tmp_path: Path) -> None:
    from omnisort_hw.core.camera_model import OcamModel
    from sim_backend.dataset import checkerboard_views
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import camera_model_for, render_scene
    from sim_backend.sort_harness import sim_registration_config

    views = tmp_path / "views"
    checkerboard_views(views, n=10, seed=1, width=WIDTH, progress=False)
    scene = sized(load_scene(SCENE), WIDTH, WIDTH)
    truth_model = camera_model_for(scene)
    _, truth = render_scene(scene, with_truth=True)
    assert truth is not None
    reg = sim_registration_config(scene)

    cfg = tmp_path / "cell.toml"
    sim = f'backend = "sim"\nscene = "{SCENE}"\n'
    cfg.write_text(
        f"[camera]\n{sim}width = {WIDTH}\nheight = {WIDTH}\n[laser]\n{sim}[arm]\n{sim}"
        f'[storage]\nstate_dir = "state"\nmax_age_days = 1\n'
        f'[logging]\nlog_dir = "logs"\nrrd_keep = 3\n'
        # What an installer measures on a real cell; here from the scene file.
        f"[sorting]\nfrom_scene = true\n"
        f'[registration]\nboard = "{reg.board.cols}x{reg.board.rows}"\n'
        f"square_mm = {reg.board.square_mm}\noffset = {list(reg.offset)}\n"
        f"camera_height_mm = {reg.camera_height_mm}\n"
        f'[target]\nkind = "two-sided"\nseparation_mm = {truth["target"]["separation_mm"]}\n'
    )
    ran: dict[str, str] = {}
    figures: dict[str, float] = {}
    core_problems: list[str] = []
    sorted_any = False
    svc = start_service(cfg, tmp_path)
    proc, port = svc.proc, svc.port
    try:
        with _Diagnosed(Client("127.0.0.1", port, timeout_s=120), proc, tmp_path) as c:
            st = c.call("status")["result"]
            assert st["state"] == "idle"
            assert st["devices"]["camera"]["serial"].startswith(f"SIM-{SCENE}-{WIDTH}x{WIDTH}")
            assert st["calibration"]["motion_allowed"] is False
            r = c.call("move", {"joints_deg": [180, -60, -120, -90, 90, 10]})
            assert r["error"]["code"] == "motion_refused"

            # Intrinsics from a folder of rendered checkerboard views, against the true model.
            r = c.call("calibrate", {"what": "intrinsics", "folder": str(views), "square_mm": 116})
            assert r["ok"], r
            assert r["result"]["rms_px"] < 0.2
            stored = json.loads((tmp_path / "state" / "camera.json").read_text())
            model = OcamModel.from_dict(stored)
            assert np.allclose(model.center_uv, truth_model.center_uv, atol=1.0)
            # Inside the image circle, where the calibration views put the board.
            rad, ang = np.meshgrid(np.linspace(0, 0.85 * WIDTH / 2, 6), np.linspace(0, 6.2, 12))
            pix = truth_model.center_uv + np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
            pix = pix.reshape(-1, 2)
            err = _angle_deg(model.pixel_to_ray(pix), truth_model.pixel_to_ray(pix))
            assert err.max() < 0.2, err.max()
            ran["intrinsics"] = f"rms {r['result']['rms_px']:.3f} px, ray error {err.max():.3f} deg"

            # Extrinsics from a fresh capture of the two-sided target, against the truth.
            r = c.call("calibrate", {"what": "extrinsics", "target": "two-sided"})
            if r["ok"]:
                p = r["result"]["parameters"]
                system = json.loads((tmp_path / "state" / "system.json").read_text())
                R = np.asarray(system["camera_rotation"]["matrix"])
                R_true = np.asarray(truth["camera_rotation"]["matrix"])
                rot_err = float(
                    np.degrees(np.arccos(np.clip((np.trace(R.T @ R_true) - 1) / 2, -1, 1)))
                )
                d_err = abs(p["laser_distance_mm"] - truth["laser_plane"]["distance_mm"])
                n_err = float(
                    _angle_deg(
                        np.asarray(system["laser_plane"]["normal"]),
                        np.asarray(truth["laser_plane"]["normal"]),
                    )
                )
                figures.update(rotation_deg=rot_err, laser_normal_deg=n_err, distance_mm=d_err)
                ran["extrinsics"] = (
                    f"{r['result']['method']}: camera rotation error {rot_err:.3f} deg, laser "
                    f"normal {n_err:.3f} deg, distance {d_err:.1f} mm"
                )
            else:
                code = r["error"]["code"]
                assert code in CORE_ERRORS, r
                ran["extrinsics"] = f"{code}: {r['error']['message']}"
                if code != "not_available":
                    core_problems.append(ran["extrinsics"])

            # Laser map of the scene, against the truth's laser polylines.
            r = c.call("map", {"points": True, "picture": True})
            if r["ok"]:
                res = r["result"]
                assert res["points_on_plane"] > 50 and res["segments"], res
                assert res["verdict"]["level"] == "pass", res["verdict"]
                # The points are drawn on the scene (a laser-off frame), not on the capture's
                # laser light, which is black but for the stripe (its median pixel is 0).
                scene = cv2.imread(res["overlay_png"])[:, :WIDTH]
                assert np.median(scene) > 10, np.median(scene)
                pts = np.asarray(res["points_S"], float)
                truth_pts = _polyline_samples(truth["laser_polylines_S"])
                d = np.min(np.linalg.norm(pts[:, None, :] - truth_pts[None], axis=2), axis=1)
                figures["map_median_mm"] = float(np.median(d))
                ran["map"] = (
                    f"{len(pts)} points, {len(res['segments'])} segments, median distance to "
                    f"the true laser lines {np.median(d):.1f} mm"
                )
            else:
                code = r["error"]["code"]
                assert code in CORE_ERRORS | {"bad_calibration_file"}, r
                ran["map"] = f"{code}: {r['error']['message']}"

            # Robot registration from the floor board, against the true T_SB.
            r = c.call("register_robot")
            if r["ok"]:
                T = np.asarray(r["result"]["robot_base"]["matrix"])
                T_true = np.asarray(truth["robot_base"]["matrix"])
                t_err = float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))
                R_rel = T[:3, :3].T @ T_true[:3, :3]
                r_err = float(np.degrees(np.arccos(np.clip((np.trace(R_rel) - 1) / 2, -1, 1))))
                figures.update(base_mm=t_err, base_deg=r_err)
                ran["register_robot"] = f"base error {t_err:.1f} mm, {r_err:.2f} deg"
                assert r["result"]["verdict"]["level"] == "pass", r["result"]["verdict"]
                assert Path(r["result"]["overlay_png"]).is_file()
                st = c.call("status")["result"]["calibration"]
                assert st["robot_registered"] is True
            else:
                code = r["error"]["code"]
                assert code in CORE_ERRORS, r
                ran["register_robot"] = f"{code}: {r['error']['message']}"
                core_problems.append(ran["register_robot"])

            # Located cubes against the true cubes of the same colour.
            true_cubes = {
                cube["colour"]: np.asarray(cube["center_S_mm"]) for cube in truth["cubes"]
            }
            r = c.call("locate")
            located: dict[str, np.ndarray] = {}
            if r["ok"]:
                assert Path(r["result"]["overlay_png"]).is_file()
                for cube in r["result"]["cubes"]:
                    located[cube["color"]] = np.asarray(cube["center_S_mm"])
                errs = {k: float(np.linalg.norm(v - true_cubes[k])) for k, v in located.items()}
                assert set(located) <= set(true_cubes), located
                figures["locate_mm"] = max(errs.values()) if errs else float("inf")
                if len(located) < len(true_cubes):
                    core_problems.append(f"locate found {sorted(located)} of {sorted(true_cubes)}")
                ran["locate"] = f"{len(located)}/{len(true_cubes)} cubes, errors (mm) " + str(
                    {k: round(v, 1) for k, v in errs.items()}
                )
            else:
                code = r["error"]["code"]
                assert code in CORE_ERRORS | {"motion_refused"}, r
                ran["locate"] = f"{code}: {r['error']['message']}"
                core_problems.append(ran["locate"])

            # Sort, with status polled from another connection meanwhile; then the cubes
            # reported sorted must be gone from where the simulator had them.
            events: list[dict] = []
            seen, poll_errors = _poll_status_while(
                port, lambda: c.call("sort", on_event=events.append)
            )
            r = seen.pop("reply")
            # The progress events asked for came before the reply: started, then what the
            # sorter reports (the count located, then one line per cube outcome).
            assert events and events[0] == {
                "stage": "started",
                "cmd": "sort",
                "expected_s": None,
            }, events[:3]
            assert not poll_errors, poll_errors
            assert "sorting" in seen["states"], seen
            if r["ok"]:
                totals = r["result"]["totals"]
                sorted_colours = [
                    o["color"] for o in r["result"]["cubes"] if o["status"] == "sorted"
                ]
                after = c.call("locate")
                assert after["ok"], after
                left = {
                    cube["color"]: np.asarray(cube["center_S_mm"])
                    for cube in after["result"]["cubes"]
                }
                for colour in sorted_colours:
                    if colour in left:
                        assert np.linalg.norm(left[colour] - true_cubes[colour]) > 50.0, colour
                sorted_any = totals["sorted"] > 0
                reported = {e["cube"]: e["status"] for e in events if "cube" in e}
                for o in r["result"]["cubes"]:
                    if o["status"] == "sorted":
                        assert reported.get(o["index"]) == "sorted", (o, events)
                assert any("to_pick" in e for e in events), events
                if totals["cubes"] >= 2:
                    assert seen["progress_max"] >= 1, "no sort progress seen in status"
                ran["sort"] = (
                    f"{totals['sorted']}/{totals['cubes']} sorted, {totals['skipped']} skipped, "
                    f"{totals['failed']} failed; {len(left)} cubes left in view; status polled "
                    f"{seen['count']} times meanwhile"
                )
                if totals["sorted"] < totals["cubes"]:
                    core_problems.append(f"sort: {ran['sort']}")
            else:
                code = r["error"]["code"]
                assert code in CORE_ERRORS | {"motion_refused", "device_error"}, r
                ran["sort"] = f"{code}: {r['error']['message']}"
                core_problems.append(ran["sort"])
            st = c.call("status")["result"]
            assert st["state"] == "idle", st
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 0
    finally:
        svc.stop()
    log = (tmp_path / "serve.log").read_text()
    assert "stopped cleanly" in log and "Traceback" not in log
    rrds = sorted((tmp_path / "logs").glob("*.rrd"))
    paths = entity_paths(rrds[-1])
    assert {"/service/state", "/calibration/intrinsics/rms_px", "/intrinsics/image"} <= paths
    # Each stage that ran left its entities in the run's .rrd file.
    stage_entities = {
        "rotation_deg": {"/extrinsics/image", "/extrinsics/joint/result"},
        "map_median_mm": {"/map/image/laser", "/map/points_S"},
        "base_mm": {"/registration/image", "/registration/T_SB"},
        "locate_mm": {"/sorting/image", "/sorting/cubes_S"},
    }
    for figure, entities in stage_entities.items():
        if figure in figures:
            assert entities <= {p.rsplit("/", 1)[0] for p in paths} | paths, (figure, entities)
    if sorted_any:
        assert {"/sorting/planned/moves", "/sorting/executed/tcp", "/arm/command"} <= paths
    print("\n" + "\n".join(f"{k:>15}: {v}" for k, v in ran.items()))
    # Accuracy of the whole chain on this scene. At 960 px a pixel subtends twice the angle it
    # does at 1920 px, so the 1920 px goals are doubled: camera rotation and laser normal
    # 0.06 deg, laser distance 2 mm; the laser map within a pixel's footprint at 1 m (3.4 mm);
    # robot base and cubes within the registration and location goals (2 mm, 0.2 deg).
    tolerance = {
        "rotation_deg": 0.06,
        "laser_normal_deg": 0.06,
        "distance_mm": 2.0,
        "map_median_mm": 3.4,
        "base_mm": 2.0,
        "base_deg": 0.2,
        "locate_mm": 2.0,
    }
    assert set(figures) == set(tolerance), (figures, ran)
    off = {k: v for k, v in figures.items() if v > tolerance[k]}
    if off:
        core_problems.append(f"accuracy outside tolerance: {off}")
    assert not core_problems, f"core on the {SCENE} scene: {'; '.join(core_problems)}"
