"""One `.rrd` file per run in the log directory, rotated by count and total size.

`rotate_rrd_files` deletes the oldest files until at most `keep` remain and they add up to at
most `max_total_bytes`; the file being written is never deleted. `RunLogRotator` holds the
service's current `RunLog` and starts a new file when the current one grows past its size
limit (only between jobs, so a job's entries stay in one file).
"""

from __future__ import annotations

import logging
import os
import threading
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from omnisort_hw.runlog import RunLog

log = logging.getLogger(__name__)
RRD_GLOB = "*.rrd"


@dataclass(frozen=True)
class RotationResult:
    """What a rotation kept and deleted."""

    kept: list[Path]
    deleted: list[Path]
    total_bytes: int


def rrd_files(log_dir: str | Path) -> list[Path]:
    """The `.rrd` files of `log_dir`, oldest first (by modification time, then name)."""
    folder = Path(log_dir)
    if not folder.is_dir():
        return []
    files = []
    for p in folder.glob(RRD_GLOB):
        try:
            files.append((p.stat().st_mtime_ns, p.name, p))
        except FileNotFoundError:
            continue
    return [p for _, _, p in sorted(files)]


def rotate_rrd_files(
    log_dir: str | Path,
    keep: int,
    max_total_bytes: int | None = None,
    protect: Iterable[str | Path] = (),
) -> RotationResult:
    """Delete the oldest `.rrd` files beyond `keep` files or `max_total_bytes` in all."""
    protected = {Path(p).resolve() for p in protect}
    files = rrd_files(log_dir)
    sizes = {}
    for p in files:
        try:
            sizes[p] = p.stat().st_size
        except FileNotFoundError:
            sizes[p] = 0
    total = sum(sizes.values())
    count = len(files)
    deleted: list[Path] = []
    for p in files:
        over_count = count > keep
        over_size = max_total_bytes is not None and total > max_total_bytes
        if not (over_count or over_size):
            break
        if p.resolve() in protected:
            continue
        try:
            p.unlink()
        except FileNotFoundError:
            pass
        except OSError as exc:
            log.warning("could not delete old run log %s: %s", p, exc)
            continue
        deleted.append(p)
        total -= sizes[p]
        count -= 1
    kept = [p for p in files if p not in deleted]
    return RotationResult(kept=kept, deleted=deleted, total_bytes=total)


def new_run_path(log_dir: str | Path, prefix: str = "omnisort") -> Path:
    """`LOG_DIR/PREFIX-YYYYmmddTHHMMSS.ffffffZ-PID.rrd`: sortable and unique per process."""
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    return Path(log_dir) / f"{prefix}-{stamp}-{os.getpid()}.rrd"


class RunLogRotator:
    """The service's current RunLog, replaced by a fresh file when it grows too large."""

    def __init__(
        self,
        log_dir: str | Path | None,
        keep: int = 20,
        max_total_bytes: int | None = None,
        max_file_bytes: int | None = None,
        prefix: str = "omnisort",
    ) -> None:
        self.log_dir = Path(log_dir) if log_dir is not None else None
        self.keep = keep
        self.max_total_bytes = max_total_bytes
        self.max_file_bytes = max_file_bytes
        self.prefix = prefix
        self._lock = threading.Lock()
        self._log = RunLog(None)
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            self._log = RunLog(new_run_path(self.log_dir, self.prefix))
            self.rotate()

    @property
    def log(self) -> RunLog:
        """The RunLog to write to now."""
        return self._log

    @property
    def path(self) -> Path | None:
        return self._log.path

    def rotate(self) -> RotationResult | None:
        """Apply the count and size limits, never deleting the current file."""
        if self.log_dir is None:
            return None
        current = [self._log.path] if self._log.path is not None else []
        result = rotate_rrd_files(self.log_dir, self.keep, self.max_total_bytes, protect=current)
        for p in result.deleted:
            log.info("deleted old run log %s", p)
        return result

    def roll_if_needed(self) -> bool:
        """Start a new file if the current one is over `max_file_bytes`; True when it did."""
        path = self._log.path
        if path is None or self.max_file_bytes is None:
            return False
        try:
            size = path.stat().st_size
        except FileNotFoundError:
            return False
        if size <= self.max_file_bytes:
            return False
        with self._lock:
            old = self._log
            self._log = RunLog(new_run_path(self.log_dir or path.parent, self.prefix))
            old.close()
        log.info("run log %s reached %d bytes; continuing in %s", path, size, self._log.path)
        self.rotate()
        return True

    def close(self) -> None:
        """Flush and close the current file."""
        with self._lock:
            self._log.close()
