"""Rotation of the per-run `.rrd` files by count and total size, and rolling by file size."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from omnisort_hw.runlog import entity_paths
from omnisort_hw.service.rrd import RunLogRotator, rotate_rrd_files, rrd_files


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
