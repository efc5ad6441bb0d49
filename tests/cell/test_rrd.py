"""Rotation of the per-run `.rrd` files by count and total size, and rolling by file size."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from omnisort_hw.cell.rrd import RunLogRotator, rotate_rrd_files, rrd_files
from omnisort_hw.runlog import entity_paths


def _make(folder: Path, name: str, size: int, age_s: float) -> Path:
    p = folder / name
    p.write_bytes(b"\0" * size)
    t = time.time() - age_s
    os.utime(p, (t, t))
    return p


def test_rotation_by_count_keeps_the_newest(tmp_path: Path) -> None:
    files = [_make(tmp_path, f"run{i}.rrd", 10, age_s=100 - i) for i in range(6)]
    (tmp_path / "notes.txt").write_text("not a run log")
    result = rotate_rrd_files(tmp_path, keep=3)
    assert result.deleted == files[:3]
    assert rrd_files(tmp_path) == files[3:]
    assert (tmp_path / "notes.txt").exists()


def test_rotation_by_total_size(tmp_path: Path) -> None:
    files = [_make(tmp_path, f"run{i}.rrd", 1000, age_s=100 - i) for i in range(5)]
    result = rotate_rrd_files(tmp_path, keep=100, max_total_bytes=2500)
    assert result.deleted == files[:3]
    assert result.total_bytes == 2000


def test_rotation_never_deletes_the_current_file(tmp_path: Path) -> None:
    current = _make(tmp_path, "current.rrd", 5000, age_s=1000)
    others = [_make(tmp_path, f"run{i}.rrd", 10, age_s=10 - i) for i in range(3)]
    result = rotate_rrd_files(tmp_path, keep=1, max_total_bytes=100, protect=[current])
    assert current.exists()
    assert set(result.deleted) == set(others)


def test_rotator_rolls_to_a_new_file_and_keeps_count(tmp_path: Path) -> None:
    for i in range(4):
        _make(tmp_path, f"omnisort-old{i}.rrd", 10, age_s=1000 - i)
    rot = RunLogRotator(tmp_path, keep=3, max_file_bytes=20_000)
    first = rot.path
    assert first is not None and first.exists()
    assert len(rrd_files(tmp_path)) == 3
    rot.log.event("service/state", "idle -> sorting")
    rot.log.image("camera/raw", np.random.default_rng(0).integers(0, 255, (200, 200, 3), np.uint8))
    rot.log._rec.flush()
    assert rot.roll_if_needed()
    assert rot.path != first
    rot.log.event("service/state", "sorting -> idle")
    rot.close()
    assert first in rrd_files(tmp_path)
    assert {"/service/state", "/camera/raw"} <= entity_paths(first)
    assert "/service/state" in entity_paths(rot.path)
    assert len(rrd_files(tmp_path)) == 3


_ROLL_SCRIPT = """
import sys
import numpy as np
from omnisort_hw.runlog import RunLog

def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 1e6

folder, rolls = sys.argv[1], int(sys.argv[2])
image = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
log = RunLog(None)
for i in range(rolls):
    log.reopen(f"{folder}/run-{i:03d}.rrd")
    for step in range(2):
        log.set_step("frame", step)
        log.image("camera/image", image)
    if i == 4:
        start = rss_mb()
log.close()
print(start, rss_mb())
"""


def test_rolling_the_run_log_keeps_memory_flat(tmp_path: Path) -> None:
    """A service rolls its run log for days: each roll must not keep what was logged before.
    Each roll here logs 1.8 MB of images; a log that kept even a third of that per file would
    grow by more than 40 MB over 75 rolls, while allocator noise stays within a few MB."""
    import subprocess
    import sys

    rolls = 80
    out = subprocess.run(
        [sys.executable, "-c", _ROLL_SCRIPT, str(tmp_path), str(rolls)],
        capture_output=True,
        text=True,
        timeout=240,
        check=True,
    )
    start, end = (float(v) for v in out.stdout.split())
    assert end - start < 40.0, f"RSS grew {end - start:.1f} MB over {rolls - 5} rolls"
    last = tmp_path / f"run-{rolls - 1:03d}.rrd"
    assert "/camera/image" in entity_paths(last)
    assert "/camera/image" in entity_paths(tmp_path / "run-000.rrd")


_KILLED_SCRIPT = """
import os, signal, sys
import numpy as np
from omnisort_hw.runlog import RunLog

log = RunLog(sys.argv[1])
for step in range(10):
    log.set_step("frame", step)
    log.image("camera/image", np.full((60, 80, 3), step, np.uint8))
    log.scalar("progress", step)
log._rec.flush()
os.kill(os.getpid(), signal.SIGKILL)
"""


def _has_footer(path: Path) -> bool:
    import warnings

    from rerun.chunk import RrdReader

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        RrdReader(str(path))
    return not any("footer" in str(w.message) for w in caught)


def test_a_run_log_cut_off_by_sigkill_is_sealed_at_the_next_start(tmp_path: Path) -> None:
    """A killed service cannot write its `.rrd` footer; the next start rewrites that file with
    one, keeping every chunk and the file's time (rotation orders files by it)."""
    import subprocess
    import sys

    killed = tmp_path / "omnisort-20260101T000000.000000Z-1.rrd"
    proc = subprocess.run([sys.executable, "-c", _KILLED_SCRIPT, str(killed)], timeout=120)
    assert proc.returncode == -9
    assert not _has_footer(killed)
    before = killed.stat().st_mtime_ns
    rows_before = _rows(killed, "/camera/image")
    rot = RunLogRotator(tmp_path, keep=10)
    try:
        assert rot.sealed == [killed]
        assert _has_footer(killed)
        assert killed.stat().st_mtime_ns == before
        assert _rows(killed, "/camera/image") == rows_before == 10
        assert not list(tmp_path.glob("*.sealing"))
        assert rot.path != killed and rot.path is not None
    finally:
        rot.close()
    again = RunLogRotator(tmp_path, keep=10)  # finished files are left alone
    again.close()
    assert again.sealed == []


def _rows(path: Path, entity: str) -> int:
    import warnings

    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sum(
            c.num_rows for c in RrdReader(str(path)).stream() if str(c.entity_path) == entity
        )
