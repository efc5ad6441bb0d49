"""A sweep on disk: `manifest.json` (the trials, in order) and `rows.jsonl` (one finished
trial per line, appended as each finishes).

A row is written whole with one write, flushed and fsynced before the next, so a kill leaves
at most a torn last line; opening the store cuts it off (that trial runs again). A torn line
anywhere else, or a row of a trial the manifest does not hold, is a typed error naming the
file and line: someone else wrote there.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omnisort_hw.errors import InputError
from omnisort_hw.fileio import atomic_write_json
from omnisort_hw.sweeps.trial import Trial, canonical_json

MANIFEST = "manifest.json"
ROWS = "rows.jsonl"


class SweepStore:
    """The manifest and rows of one sweep directory (see module docstring)."""

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.dir = Path(directory)
        self.manifest_path = self.dir / MANIFEST
        self.rows_path = self.dir / ROWS

    def open(self, trials: Sequence[Trial], meta: dict[str, Any]) -> dict[str, dict[str, Any]]:
        """Create the sweep, or reopen the same one; returns the finished rows by key.
        InputError when the directory holds another sweep's manifest."""
        self.dir.mkdir(parents=True, exist_ok=True)
        listed = [t.to_dict() for t in trials]
        keys = [t["key"] for t in listed]
        if len(set(keys)) != len(keys):
            raise InputError("the sweep lists the same trial twice (same config and seed)")
        if self.manifest_path.is_file():
            try:
                old = json.loads(self.manifest_path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise InputError(f"{self.manifest_path}: unreadable manifest ({exc})") from None
            if [t.get("key") for t in old.get("trials", [])] != keys:
                raise InputError(
                    f"{self.manifest_path}: this folder holds another sweep "
                    f"({len(old.get('trials', []))} trials, not these {len(keys)}); "
                    "give another --sweep-dir or remove it"
                )
        else:
            atomic_write_json(self.manifest_path, {**meta, "trials": listed}, keep_history=False)
        return self.finished(set(keys))

    def finished(self, keys: set[str] | None = None) -> dict[str, dict[str, Any]]:
        """The rows written so far, by key; a torn last line is cut off the file."""
        if not self.rows_path.is_file():
            return {}
        data = self.rows_path.read_bytes()
        good_end = data.rfind(b"\n") + 1
        if good_end < len(data):  # a kill mid-write: the last line is torn
            with self.rows_path.open("r+b") as f:
                f.truncate(good_end)
                f.flush()
                os.fsync(f.fileno())
        rows: dict[str, dict[str, Any]] = {}
        for no, line in enumerate(data[:good_end].splitlines(), 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except ValueError:
                raise InputError(f"{self.rows_path}:{no}: not a JSON row") from None
            key = row.get("key") if isinstance(row, dict) else None
            if key is None or (keys is not None and key not in keys):
                raise InputError(f"{self.rows_path}:{no}: a row of no trial of this sweep")
            rows[key] = row
        return rows

    def append(self, row: dict[str, Any]) -> None:
        """Add one finished trial's row (one write, then flushed to the disk)."""
        line = (canonical_json(row) + "\n").encode()
        with self.rows_path.open("ab") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())
