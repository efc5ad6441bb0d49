"""Calibration storage: checksums, history, health checks, and SIGKILL during a write."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw import fileio
from omnisort_hw.config.storage import StorageConfig
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.errors import CalibrationFileError, ConfigError, MotionRefusedError
from omnisort_hw.pipeline.calibration_store import (
    REQUIRED_KEYS,
    CalibrationStore,
    checksum_of,
    read_calibration_file,
)

PROJECT_ROOT = Path(__file__).resolve().parents[2]


MODEL = OcamModel.equidistant(640, 480, fov_deg=185.0).to_dict()


def camera_payload(tag: int = 0) -> dict:
    return {**MODEL, "rms_px": 0.1 + tag, "images_used": [f"img{tag}.png"]}


def system_payload(tag: int = 0) -> dict:
    payload = {k: {"tag": tag} for k in REQUIRED_KEYS["system"]}
    payload["residuals"] = np.arange(5, dtype=float)
    payload["created"] = "2026-01-01T00:00:00+00:00"
    return payload


def make_store(tmp_path: Path, **kw) -> CalibrationStore:
    return CalibrationStore(tmp_path / "state", **kw)


def test_roundtrip_keeps_payload_and_adds_checksum(tmp_path: Path) -> None:
    store = make_store(tmp_path, expected_serial="CAM-1")
    store.save_camera(camera_payload())
    store.save_system(system_payload())
    assert store.load_camera() == camera_payload()
    sysp = store.load_system()
    assert sysp["residuals"] == [0.0, 1.0, 2.0, 3.0, 4.0]
    doc = json.loads(store.path("camera").read_text())
    assert doc["checksum"].startswith("sha256:")
    assert doc["storage"]["camera_serial"] == "CAM-1"
    assert doc["storage"]["kind"] == "camera"
    store.check_motion_allowed()
    st = store.status()
    assert st["motion_allowed"] is True
    assert st["files"]["camera"]["health"] == "ok"


def test_history_is_bounded_and_each_version_loads(tmp_path: Path) -> None:
    store = make_store(tmp_path, history_keep=3)
    for tag in range(6):
        store.save_camera(camera_payload(tag))
    versions = store.history("camera")
    assert len(versions) == 3
    tags = [read_calibration_file(v, "camera").payload["rms_px"] for v in versions]
    assert tags == pytest.approx([2.1, 3.1, 4.1])
    assert store.load_camera()["rms_px"] == pytest.approx(5.1)
    model = store.camera_model()
    assert model.image_size == (640, 480)


def test_missing_files_block_motion(tmp_path: Path) -> None:
    store = make_store(tmp_path)
    with pytest.raises(MotionRefusedError, match="camera missing"):
        store.check_motion_allowed()
    with pytest.raises(CalibrationFileError, match=r"camera\.json: missing"):
        store.load_camera()
    assert store.status()["motion_allowed"] is False


@pytest.mark.parametrize(
    ("mutate", "needle"),
    [
        (lambda t: t[: len(t) // 2], "not valid JSON"),
        (lambda t: t.replace('"model": "ocam"', '"model": "0cam"'), "checksum mismatch"),
        (lambda t: "[1, 2]", "not a JSON object"),
        (lambda t: json.dumps({"model": "x"}), "no checksum"),
        (lambda t: _resign(t, lambda d: d.pop("poly")), "required key.*poly"),
        (lambda t: _resign(t, lambda d: d["storage"].update(kind="system")), "not 'camera'"),
        (lambda t: _resign(t, lambda d: d["storage"].update(saved="yesterday")), "ISO"),
        (lambda t: "\udcff", "not valid JSON"),
    ],
)
def test_corrupt_camera_file_is_a_clear_error(tmp_path: Path, mutate, needle: str) -> None:
    store = make_store(tmp_path)
    store.save_camera(camera_payload())
    store.save_system(system_payload())
    path = store.path("camera")
    path.write_bytes(mutate(path.read_text()).encode("utf-8", "surrogateescape"))
    with pytest.raises(CalibrationFileError, match=needle) as info:
        store.load_camera()
    assert "camera.json" in str(info.value)
    health = store.check("camera")
    assert health.health == "corrupt"
    with pytest.raises(MotionRefusedError, match="camera corrupt"):
        store.check_motion_allowed()


def _resign(text: str, change) -> str:
    """Edit a stored document and recompute its checksum (a well-formed but wrong file)."""
    doc = json.loads(text)
    doc.pop("checksum")
    change(doc)
    doc["checksum"] = checksum_of(doc)
    return json.dumps(doc)


def test_required_system_keys_are_checked(tmp_path: Path) -> None:
    store = make_store(tmp_path)
    bad = system_payload()
    del bad["laser_plane"]
    with pytest.raises(CalibrationFileError, match="laser_plane"):
        store.save_system(bad)
    with pytest.raises(CalibrationFileError, match="reserved"):
        store.save_camera({**MODEL, "checksum": "x"})
    with pytest.raises(CalibrationFileError, match="without poly"):
        store.save_camera({k: v for k, v in MODEL.items() if k != "poly"})


def test_stale_and_wrong_serial_block_motion(tmp_path: Path) -> None:
    now = [1_800_000_000.0]
    store = make_store(tmp_path, max_age_days=2.0, expected_serial="CAM-1", clock=lambda: now[0])
    store.save_camera(camera_payload())
    store.save_system(system_payload())
    store.check_motion_allowed()
    now[0] += 3 * 86400
    assert store.check("system").health == "stale"
    with pytest.raises(MotionRefusedError, match="stale"):
        store.check_motion_allowed()
    fresh = CalibrationStore(store.state_dir, expected_serial="CAM-2", clock=lambda: now[0])
    assert fresh.check("camera").health == "wrong_serial"
    assert "CAM-2" in fresh.check("camera").message
    with pytest.raises(MotionRefusedError, match="wrong_serial"):
        fresh.check_motion_allowed()


def test_storage_config_parsing(tmp_path: Path) -> None:
    cfg = StorageConfig.from_mapping(
        {"state_dir": "state", "max_age_days": 30, "history_keep": 5}, base_dir=tmp_path
    )
    assert cfg.state_dir == tmp_path / "state"
    assert cfg.max_age_days == 30.0
    assert StorageConfig.from_mapping({"max_age_days": 0}).max_age_days is None
    with pytest.raises(ConfigError, match="unknown"):
        StorageConfig.from_mapping({"bogus": 1})
    with pytest.raises(ConfigError, match="history_keep"):
        StorageConfig.from_mapping({"history_keep": -1})


def test_stale_temp_files_are_removed(tmp_path: Path) -> None:
    store = make_store(tmp_path)
    store.save_camera(camera_payload())
    leftover = store.state_dir / ".camera.json.abc.tmp"
    leftover.write_text("half")
    assert store.remove_stale_temps() == [leftover]
    assert not leftover.exists()


WRITER = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    from omnisort_hw.pipeline.calibration_store import CalibrationStore
    import json
    store = CalibrationStore(Path(sys.argv[1]), history_keep=4, expected_serial="CAM-1")
    model = json.loads(Path(sys.argv[3]).read_text())
    big = [float(i) * 0.5 for i in range(150_000)]
    tag = int(sys.argv[2])
    print("ready", flush=True)
    first = True
    while True:
        tag += 1
        store.save_camera({**model, "tag": tag, "table": big})
        if first:
            print("saved", flush=True)
            first = False
    """
)


@pytest.mark.timeout(90)
def test_sigkill_during_write_keeps_a_loadable_calibration(tmp_path: Path) -> None:
    """A writer killed at random moments never leaves a current file that fails to load."""
    state = tmp_path / "state"
    store = CalibrationStore(state, history_keep=4, expected_serial="CAM-1")
    store.save_camera({**MODEL, "tag": 0, "table": []})
    rng = random.Random(7)
    model_file = tmp_path / "model.json"
    model_file.write_text(json.dumps(MODEL))
    env = dict(os.environ, PYTHONPATH=str(PROJECT_ROOT))
    last_tag = 0
    kills = 0
    advanced = 0
    for run in range(12):
        start = (run + 1) * 1_000_000
        proc = subprocess.Popen(
            [sys.executable, "-c", WRITER, str(state), str(start), str(model_file)],
            stdout=subprocess.PIPE,
            env=env,
        )
        try:
            assert proc.stdout is not None
            assert proc.stdout.readline().strip() == b"ready"
            if run % 2:  # every other run: killed only after a save completed, however slow
                assert proc.stdout.readline().strip() == b"saved"
            time.sleep(rng.uniform(0.02, 1.0))
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            kills += 1
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
        rec = store.read("camera")
        assert rec.checksum.startswith("sha256:")
        assert rec.camera_serial == "CAM-1"
        tag = rec.payload["tag"]
        assert tag == last_tag or start < tag < start + 1_000_000
        advanced += tag != last_tag
        last_tag = tag
        for old in store.history("camera"):
            read_calibration_file(old, "camera")
        assert store.check("camera").ok
        store.remove_stale_temps()
    assert kills == 12
    assert advanced >= 1, "no write completed before a kill; the test proved nothing"
    assert not list(state.glob(".*.tmp"))
    assert fileio.history_versions(store.path("camera"))


def test_robot_base_is_optional_but_required_for_planned_motions(tmp_path: Path) -> None:
    store = make_store(tmp_path)
    store.save_camera(camera_payload())
    store.save_system(system_payload())
    store.check_motion_allowed()
    assert store.status()["robot_registered"] is False
    with pytest.raises(MotionRefusedError, match="register_robot"):
        store.check_motion_allowed(require_robot_base=True)
    store.save_system({**system_payload(), "robot_base": {"matrix": np.eye(4), "xyz_mm": [0] * 3}})
    store.check_motion_allowed(require_robot_base=True)
    assert store.status()["robot_registered"] is True
