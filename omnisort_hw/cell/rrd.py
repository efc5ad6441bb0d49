"""One `.rrd` file per run in the log directory, rotated by count and total size.

`rotate_rrd_files` deletes the oldest files until at most `keep` remain and they add up to at
most `max_total_bytes`; the file being written is never deleted. `RunLogRotator` holds the
service's current `RunLog` and starts a new file when the current one grows past its size
limit, during jobs too, and notices a deleted or replaced log directory.
"""

from __future__ import annotations

import contextlib
import logging
import os
import subprocess
import sys
import threading
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from omnisort_hw.runlog import RunLog

log = logging.getLogger(__name__)
RRD_GLOB = "*.rrd"
# A file is rolled once it passes this fraction of its limit, so that what is written until the
# next check (every second) still fits under the limit.
ROLL_AT = 0.9


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


SEALING_SUFFIX = ".sealing"


SEAL_TIMEOUT_S = 60.0


def _lacks_footer(path: Path) -> bool:
    """True for an `.rrd` without its footer, as rerun's own reader judges it (it warns); the
    reader opens a finished file from its footer alone (about 1 ms for 333 MB)."""
    from rerun.chunk import RrdReader

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        RrdReader(str(path))
    return any("footer" in str(w.message) for w in caught)


def _rewrite_with_footer(path: str) -> None:
    """Rewrite `path` with every chunk and a footer, atomically and with its times kept. Runs in
    a child process: rerun keeps what a recording stream was sent for the life of the process
    (sealing a 167 MB file left the caller 177 MB larger)."""
    import rerun as rr
    from rerun.chunk import RrdReader

    src = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = RrdReader(str(src))
        stores = reader.recordings()
        if not stores:
            return
        tmp = src.with_name(src.name + SEALING_SUFFIX)
        st = src.stat()
        try:
            rec = rr.RecordingStream(stores[0].application_id, recording_id=stores[0].recording_id)
            rec.save(str(tmp))
            rec.send_chunks(reader.stream())
            rec.flush()
            rec.disconnect()
            os.utime(tmp, ns=(st.st_atime_ns, st.st_mtime_ns))
            os.replace(tmp, src)
        finally:
            tmp.unlink(missing_ok=True)


def seal_unfinished_rrd(path: str | Path) -> bool:
    """Rewrite an `.rrd` that a killed process left without its footer (every chunk kept, same
    recording), atomically and with its times kept, in a child process; True when it was sealed.
    A finished file is left alone. Raises OSError when the rewrite fails or outlasts
    SEAL_TIMEOUT_S."""
    src = Path(path)
    if not _lacks_footer(src):
        return False
    code = "import sys; from omnisort_hw.cell.rrd import _rewrite_with_footer as f; f(sys.argv[1])"
    try:
        subprocess.run(
            [sys.executable, "-c", code, str(src)],
            capture_output=True,
            text=True,
            timeout=SEAL_TIMEOUT_S,
            check=True,
        )
    except subprocess.CalledProcessError as exc:
        raise OSError(f"sealing {src} failed: {exc.stderr.strip()[-300:]}") from None
    except subprocess.TimeoutExpired:
        raise OSError(f"sealing {src} took over {SEAL_TIMEOUT_S:g} s") from None
    return not _lacks_footer(src)


def seal_unfinished_rrds(log_dir: str | Path) -> list[Path]:
    """Seal every unfinished `.rrd` of `log_dir` (see `seal_unfinished_rrd`) and drop the
    leftovers of a sealing that was itself cut off; never raises. The sealed files."""
    folder = Path(log_dir)
    for leftover in folder.glob(RRD_GLOB + SEALING_SUFFIX):
        leftover.unlink(missing_ok=True)
    sealed = []
    for p in rrd_files(folder):
        try:
            if seal_unfinished_rrd(p):
                sealed.append(p)
                log.warning("run log %s was cut off (no footer); sealed it", p)
        except Exception as exc:
            log.warning("could not seal the cut-off run log %s: %s", p, exc)
    return sealed


@dataclass(frozen=True)
class LogHealth:
    """What `status` says about the run log: ok, or the problem and since when."""

    ok: bool
    rrd: str | None
    problem: str | None = None
    since: str | None = None


def _dir_identity(folder: Path) -> tuple[int, int] | None:
    try:
        st = folder.stat()
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


class RunLogRotator:
    """The service's current RunLog, moved to a fresh file when the current one grows past its
    size limit (during a job as well: the RunLog object stays the same, only its file changes),
    when the file or the folder is deleted or replaced, and never raising: a folder that cannot
    be written turns the run log off (the service logs to stderr only) until it can be again.
    """

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
        self._dir_id: tuple[int, int] | None = None
        self._problem: str | None = None
        self._since: str | None = None
        self.sealed: list[Path] = []
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            self.sealed = seal_unfinished_rrds(self.log_dir)
            self._open("started")

    @property
    def log(self) -> RunLog:
        """The RunLog to write to (always the same object; it follows the file changes)."""
        return self._log

    @property
    def path(self) -> Path | None:
        return self._log.path

    def health(self) -> LogHealth:
        path = self._log.path
        return LogHealth(
            self._problem is None, str(path) if path else None, self._problem, self._since
        )

    def _open(self, reason: str) -> None:
        assert self.log_dir is not None
        old = self._log.path
        self._log.reopen(new_run_path(self.log_dir, self.prefix))
        self._dir_id = _dir_identity(self.log_dir)
        if old is not None:
            level = logging.INFO if reason.startswith("reached") else logging.WARNING
            log.log(level, "run log %s: %s; continuing in %s", old, reason, self._log.path)
        if self._problem is not None:
            log.warning("run log restored in %s (was: %s)", self._log.path, self._problem)
            self._problem = self._since = None
        self.rotate()

    def _reason_for_new_file(self) -> str | None:
        assert self.log_dir is not None
        path = self._log.path
        if path is None:
            return "run log off after a failure; retrying"
        if _dir_identity(self.log_dir) != self._dir_id:
            return f"log directory {self.log_dir} was deleted or replaced"
        try:
            size = path.stat().st_size
        except FileNotFoundError:
            return "the file was deleted"
        if self.max_file_bytes is not None and size > ROLL_AT * self.max_file_bytes:
            return f"reached {size} bytes (limit {self.max_file_bytes})"
        return None

    def check(self) -> bool:
        """Roll, notice a deleted or replaced file or folder, or degrade; never raises. True
        when a new file was started."""
        if self.log_dir is None:
            return False
        with self._lock:
            try:
                reason = self._reason_for_new_file()
                if reason is None:
                    return False
                self._open(reason)
                return True
            except Exception as exc:
                self._degrade(exc)
                return False

    def _degrade(self, exc: BaseException) -> None:
        problem = f"run log unavailable in {self.log_dir}: {type(exc).__name__}: {exc}"
        with contextlib.suppress(Exception):
            self._log.reopen(None)
        if problem != self._problem:
            log.error("%s; logging to stderr only until it can be written again", problem)
        if self._problem is None:
            self._since = datetime.now(UTC).isoformat(timespec="seconds")
        self._problem = problem

    def roll_if_needed(self) -> bool:
        """Start a new file if the current one is over `max_file_bytes` (see `check`)."""
        return self.check()

    def rotate(self) -> RotationResult | None:
        """Apply the count and size limits, never deleting the current file."""
        if self.log_dir is None:
            return None
        current = [self._log.path] if self._log.path is not None else []
        budget = self.max_total_bytes
        if budget is not None and self.max_file_bytes is not None:
            # Room for the current file to grow to its own limit.
            budget = max(0, budget - self.max_file_bytes)
        result = rotate_rrd_files(self.log_dir, self.keep, budget, protect=current)
        for p in result.deleted:
            log.info("deleted old run log %s", p)
        return result

    def close(self) -> None:
        """Flush and close the current file."""
        with self._lock:
            self._log.close()
