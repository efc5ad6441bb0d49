"""End to end: `omnisort serve` on the simulated cell, driven through TCP, checked against truth.

The service runs as a subprocess exactly as under systemd (READY and the port come over a
real NOTIFY_SOCKET). The job goes as far as this build's core goes: every stage whose core
component exists is checked against the simulator's truth; a stage whose component is missing
must answer `not_available` naming it (never a made-up result). The test prints which stages
ran.
"""

from __future__ import annotations

import itertools
import json
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.runlog import entity_paths
from omnisort_hw.service.client import Client
from tests.service.procs import start_serve

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

    def call(self, cmd: str, args: dict | None = None) -> dict:
        from omnisort_hw.service.client import ClientError

        try:
            return self.client.call(cmd, args)
        except ClientError as exc:
            self.proc.send_signal(signal.SIGUSR1)
            time.sleep(1.0)
            log = (self.tmp / "serve.log").read_text()[-6000:]
            raise AssertionError(f"{cmd}: {exc}\n--- service log ---\n{log}") from None

    def __enter__(self) -> _Diagnosed:
        return self

    def __exit__(self, *exc: object) -> None:
        self.client.close()


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
    from sim_backend.api import camera_model_for, render_scene
    from sim_backend.dataset import checkerboard_views
    from sim_backend.scene import load_scene, sized

    views = tmp_path / "views"
    checkerboard_views(views, n=10, seed=1, width=WIDTH, progress=False)
    scene = sized(load_scene(SCENE), WIDTH, WIDTH)
    truth_model = camera_model_for(scene)
    _, truth = render_scene(scene, with_truth=True)
    assert truth is not None

    cfg = tmp_path / "cell.toml"
    sim = f'backend = "sim"\nscene = "{SCENE}"\n'
    cfg.write_text(
        f"[camera]\n{sim}width = {WIDTH}\nheight = {WIDTH}\n[laser]\n{sim}[arm]\n{sim}"
        f'[storage]\nstate_dir = "state"\nmax_age_days = 1\n'
        f'[logging]\nlog_dir = "logs"\nrrd_keep = 3\n'
    )
    ran: dict[str, str] = {}
    figures: dict[str, float] = {}
    core_problems: list[str] = []
    proc, port, rx = start_serve(cfg, tmp_path)
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
            r = c.call("map", {"points": True})
            if r["ok"]:
                res = r["result"]
                assert res["points_on_plane"] > 50 and res["segments"], res
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

            for cmd in ("register_robot", "locate", "sort"):
                r = c.call(cmd)
                if r["ok"]:
                    ran[cmd] = json.dumps(r["result"])[:200]
                else:
                    code = r["error"]["code"]
                    assert code in {"not_available", "motion_refused"}, r
                    ran[cmd] = f"{code}: {r['error']['message']}"
            st = c.call("status")["result"]
            assert st["state"] == "idle", st
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        rx.close()
    log = (tmp_path / "serve.log").read_text()
    assert "stopped cleanly" in log and "Traceback" not in log
    rrds = sorted((tmp_path / "logs").glob("*.rrd"))
    paths = entity_paths(rrds[-1])
    assert {"/service/state", "/calibration/intrinsics/rms_px", "/intrinsics/image"} <= paths
    assert "/map/points_S" in paths or "map" not in figures
    print("\n" + "\n".join(f"{k:>15}: {v}" for k, v in ran.items()))
    # Accuracy of the core on this scene (not of the service): reported, and an expected
    # failure with the figures until the core meets it, so that it is neither hidden nor lost.
    off = {
        k: v
        for k, v in figures.items()
        if v > {"rotation_deg": 1.0, "laser_normal_deg": 1.0, "distance_mm": 15.0}.get(k, 25.0)
    }
    if off:
        core_problems.append(f"accuracy outside tolerance: {off}")
    if core_problems:
        pytest.xfail(f"core on the {SCENE} scene: {'; '.join(core_problems)}")
