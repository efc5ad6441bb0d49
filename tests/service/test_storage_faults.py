"""Storage that never loses history: failed saves change nothing, say why, and do not fault.

Tests run as root, so a read-only directory does not make a write fail. Two ways that do:
- RLIMIT_FSIZE in a child process: the kernel refuses the temp file's bytes with EFBIG, for
  root too, exactly where a full disk (ENOSPC) would: a real OS failure at the real boundary;
- an OSError injected into `os.replace` (the rename after the history entry was added): the
  one step that a real failure cannot be aimed at, and the one whose rollback matters most.
"""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from omnisort_hw import fileio
from omnisort_hw.errors import StorageError
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from tests.service.conftest import Harness
from tests.service.fakes import camera_payload, system_payload

pytestmark = pytest.mark.timeout(120)
PROJECT_ROOT = Path(__file__).resolve().parents[2]


def _snapshot(state: Path) -> dict[str, bytes]:
    """Every file under `state` (relative name -> bytes)."""
    return {
        str(p.relative_to(state)): p.read_bytes() for p in sorted(state.rglob("*")) if p.is_file()
    }


def _three_versions(state: Path) -> CalibrationStore:
    store = CalibrationStore(state, history_keep=20)
    for rms in (0.1, 0.2, 0.3):
        store.save_camera({**camera_payload(), "rms_px": rms})
    assert len(store.history("camera")) == 2
    return store


FAILING_SAVES = """
import resource, signal, sys
from pathlib import Path
from omnisort_hw.errors import StorageError
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from tests.service.fakes import camera_payload

signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
store = CalibrationStore(Path(sys.argv[1]), history_keep=20)
resource.setrlimit(resource.RLIMIT_FSIZE, (64, 64))
for i in range(25):
    try:
        store.save_camera({**camera_payload(), "rms_px": 1.0 + i})
    except StorageError as exc:
        print(exc, flush=True)
"""


def test_history_intact_after_25_failed_saves(tmp_path: Path) -> None:
    state = tmp_path / "state"
    _three_versions(state)
    before = _snapshot(state)
    done = subprocess.run(
        [sys.executable, "-c", FAILING_SAVES, str(state)],
        cwd=PROJECT_ROOT,
        env={**os.environ, "PYTHONPATH": str(PROJECT_ROOT)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    messages = done.stdout.splitlines()
    assert done.returncode == 0, done.stderr[-2000:]
    assert len(messages) == 25, done.stdout[-2000:]
    assert all("camera.json" in m and "EFBIG" in m and "unchanged" in m for m in messages)
    assert _snapshot(state) == before


def test_failed_rename_takes_back_its_history_entry(tmp_path: Path, monkeypatch) -> None:
    state = tmp_path / "state"
    store = _three_versions(state)
    before = _snapshot(state)

    def refuse(src: object, dst: object) -> None:
        raise OSError(errno.EROFS, "Read-only file system", str(dst))

    monkeypatch.setattr(fileio.os, "replace", refuse)
    for i in range(25):
        with pytest.raises(StorageError, match="EROFS") as info:
            store.save_camera({**camera_payload(), "rms_px": 2.0 + i})
        assert str(store.path("camera")) in str(info.value)
    monkeypatch.undo()
    assert _snapshot(state) == before
    store.save_camera({**camera_payload(), "rms_px": 9.0})
    assert len(store.history("camera")) == 3


def test_failed_save_is_storage_error_and_not_fault(make_service, monkeypatch) -> None:
    h: Harness = make_service()
    store = h.cell.store
    before = _snapshot(Path(store.state_dir))

    def full(directory: Path, name: str, data: bytes) -> Path:
        raise OSError(errno.ENOSPC, "No space left on device", str(directory))

    monkeypatch.setattr(fileio, "write_temp", full)
    # register_robot's own work needs the simulated cell; here it is only the save.
    h.cell.jobs.register_robot = lambda image, cancel: {
        "path": str(store.save_system(system_payload()))
    }
    with h.client() as c:
        r = c.call("register_robot")
        st = c.call("status")["result"]
        monkeypatch.undo()
        moved = c.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]})
    assert r["error"]["code"] == "storage_error", r
    assert "system.json" in r["error"]["message"] and "ENOSPC" in r["error"]["message"]
    assert st["state"] == "idle" and st["motion_allowed"] is True
    assert moved["ok"], moved
    calibration = [store.path("camera").name, store.path("system").name, "history"]
    after = _snapshot(Path(store.state_dir))
    assert {k: after[k] for k in before if k.startswith(tuple(calibration))} == {
        k: v for k, v in before.items() if k.startswith(tuple(calibration))
    }


@pytest.mark.parametrize("which", ["state_dir", "log_dir"])
def test_unwritable_directories_refused_at_start(tmp_path: Path, which: str) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory\n")
    dirs = {"state_dir": tmp_path / "state", "log_dir": tmp_path / "logs"}
    dirs[which] = blocker / "sub"
    cfg = tmp_path / "cell.toml"
    cfg.write_text(
        f'[camera]\nbackend = "sim"\n[storage]\nstate_dir = "{dirs["state_dir"]}"\n'
        f'[logging]\nlog_dir = "{dirs["log_dir"]}"\n'
    )
    done = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "serve", "--config", str(cfg), "--port", "0"],
        cwd=PROJECT_ROOT,
        env={**os.environ, "PYTHONPATH": str(PROJECT_ROOT)},
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode != 0
    assert f"{which} {dirs[which]} is not writable" in done.stderr, done.stderr[-2000:]
    assert "ENOTDIR" in done.stderr
    assert "Traceback" not in done.stderr
