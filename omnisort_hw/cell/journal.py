"""The job journal: `STATE_DIR/job.json`, the last job and the cube in flight, written
atomically at every step that matters, so a crash (SIGKILL, power loss) leaves a record.

One record, replaced whole each time (temp file, fsync, rename; never half-written):

    {"format": 1, "job": "sort", "request_id": 7, "pid": 1234, "state": "running",
     "started": ISO, "updated": ISO, "ended": ISO|null, "outcome": str|null,
     "progress": [... the last 50 progress events, each stamped "at": ISO ...],
     "in_flight": {"cube": 2, "color": "red", "bin": "red", "phase": "holding", "at": ISO}|null,
     "took_s": {"calibrate extrinsics": 41.2, "map": 9.8, ...}}

`took_s` is carried from record to record: how long the last job of each kind that ended done
took on this cell (a calibration's kind by its `what`), so a job can say what to expect
(`expected_s`) before it has measured anything of its own.

`state` is running, done, stopped, failed or interrupted. A record still `running` when a new
service starts belongs to a process that died mid-job: `recover()` marks it `interrupted`
(the cell then refuses motion until `reset`; nothing resumes by itself).

Pick phases (`in_flight.phase`): `grasping` (the gripper is closing on the cube), `holding`
(the cube is in the gripper), then the record is cleared once the cube is released in its bin
or the gripper closed on nothing.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from omnisort_hw import fileio
from omnisort_hw.errors import StorageError

log = logging.getLogger(__name__)

JOURNAL_NAME = "job.json"
FORMAT = 1
PROGRESS_KEEP = 50
LOADED_PHASES = frozenset({"grasping", "holding"})


def job_kind(job: str, args: dict[str, Any]) -> str:
    """The kind of a job whose duration is kept: the command, and a calibration's `what`."""
    what = args.get("what")
    return f"{job} {what}" if isinstance(what, str) and what else job


def _copy(record: dict[str, Any] | None) -> dict[str, Any] | None:
    return json.loads(json.dumps(record)) if record is not None else None


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class JobJournal:
    """Reads and writes `STATE_DIR/job.json` (thread-safe; every write is atomic)."""

    def __init__(self, state_dir: str | os.PathLike[str]) -> None:
        self.path = Path(state_dir) / JOURNAL_NAME
        self._lock = threading.Lock()
        self._record: dict[str, Any] | None = self._read()
        # A copy of the record as of its last change, for `status` on the event loop: read
        # without the lock, which a write holds through its two fsyncs (tens of ms on a busy
        # disk); replaced whole at every change, never mutated.
        self._published = _copy(self._record)
        self.problem: str | None = None
        self._started = time.monotonic()  # of the job in the record, in this process

    def _read(self) -> dict[str, Any] | None:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            return None
        except (OSError, ValueError) as exc:
            log.error("%s: unreadable job journal (%s); starting a new one", self.path, exc)
            return None
        return data if isinstance(data, dict) and data.get("format") == FORMAT else None

    def _write(self) -> None:
        assert self._record is not None
        self._record["updated"] = _now()
        self._published = _copy(self._record)
        try:
            fileio.atomic_write_json(self.path, self._record, keep_history=False)
            self.problem = None
        except OSError as exc:
            # The job goes on (stopping a motion to save a record would be worse); the
            # problem is logged and shown in `status`.
            self.problem = f"{self.path}: {fileio.os_error_text(exc)}"
            log.error("job journal not written: %s", self.problem)

    @property
    def record(self) -> dict[str, Any] | None:
        """A copy of the current record (None before the first job); never waits for a
        write in progress. Callers must not change it (it is shared until the next change)."""
        return self._published

    def expected_s(self, job: str, args: dict[str, Any]) -> float | None:
        """How long the last job of this kind that ended done took on this cell (s), or None
        (none has yet). Read from the published copy, without the lock: the service asks on its
        event loop, which must not wait for a write's fsyncs."""
        took = (self._published or {}).get("took_s") or {}
        value = took.get(job_kind(job, args))
        return float(value) if isinstance(value, int | float) else None

    def start(self, job: str, request_id: int | str | None, args: dict[str, Any]) -> None:
        """A new job begins; an unresolved cube in flight is carried over (still unresolved),
        and so are the durations of the jobs done before (`took_s`)."""
        with self._lock:
            carried = (self._record or {}).get("in_flight")
            took = dict((self._record or {}).get("took_s") or {})
            self._started = time.monotonic()
            self._record = {
                "format": FORMAT,
                "job": job,
                "request_id": request_id,
                "args": args,
                "pid": os.getpid(),
                "state": "running",
                "started": _now(),
                "ended": None,
                "outcome": None,
                "progress": [],
                "in_flight": carried,
                "took_s": took,
            }
            self._write()

    def progress(self, event: dict[str, Any]) -> None:
        with self._lock:
            if self._record is None:
                return
            events = self._record["progress"]
            events.append({**event, "at": _now()})
            del events[:-PROGRESS_KEEP]
            self._write()

    def pick_phase(self, phase: str, cube: int, color: str, bin_: str | None) -> None:
        """Where the pick of one cube stands; `released` and `empty` clear the record."""
        with self._lock:
            if self._record is None:
                return
            if phase in LOADED_PHASES:
                self._record["in_flight"] = {
                    "cube": cube,
                    "color": color,
                    "bin": bin_,
                    "phase": phase,
                    "job": self._record["job"],
                    "at": _now(),
                }
            else:
                self._record["in_flight"] = None
            self._write()

    def clear_in_flight(self, why: str) -> None:
        """The cube in flight was placed or removed by an operator."""
        with self._lock:
            if self._record is None or self._record.get("in_flight") is None:
                return
            log.info("cube in flight cleared: %s", why)
            self._record["in_flight"] = None
            self._write()

    def finish(self, state: str, outcome: str) -> None:
        """The job ended: done, stopped or failed, with a one-line outcome."""
        with self._lock:
            if self._record is None:
                return
            self._record.update(state=state, outcome=outcome, ended=_now())
            if state == "done":
                kind = job_kind(self._record["job"], self._record.get("args") or {})
                took = dict(self._record.get("took_s") or {})
                took[kind] = round(time.monotonic() - self._started, 1)
                self._record["took_s"] = took
            self._write()

    def recover(self) -> dict[str, Any] | None:
        """At start-up: a record left `running` is marked `interrupted` and returned."""
        with self._lock:
            rec = self._record
            if rec is None or rec.get("state") != "running":
                return None
            rec.update(
                state="interrupted",
                outcome=f"the service (PID {rec.get('pid')}) ended during the job",
                ended=None,
            )
            self._write()
            return json.loads(json.dumps(rec))

    def in_flight(self) -> dict[str, Any] | None:
        with self._lock:
            rec = self._record
            return dict(rec["in_flight"]) if rec and rec.get("in_flight") else None

    def check_writable(self) -> None:
        """StorageError when the journal cannot be written (checked at start-up)."""
        fileio.check_writable(self.path.parent, "job journal directory")
        if self.problem:
            raise StorageError(self.problem)
