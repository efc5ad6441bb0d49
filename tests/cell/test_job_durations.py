"""What a long job says to expect: the job journal keeps how long the last job of each kind that
ended done took on this cell (a calibration's kind by its `what`), across jobs and restarts,
and `status`'s job line gives it beside the running time."""

from __future__ import annotations

import re
import time
from pathlib import Path

from omnisort_hw.cell.journal import JobJournal
from omnisort_hw.service.states import Job, State
from omnisort_hw.service.status_reading import job_text

EXTRINSICS = {"what": "extrinsics", "separation_mm": 1084.5}


def test_the_last_done_job_of_each_kind_is_what_to_expect(tmp_path: Path) -> None:
    journal = JobJournal(tmp_path)
    assert journal.expected_s("calibrate", EXTRINSICS) is None
    t0 = time.monotonic()
    journal.start("calibrate", 1, EXTRINSICS)
    time.sleep(0.3)
    journal.finish("done", "calibrate done")
    took = time.monotonic() - t0
    expected = journal.expected_s("calibrate", EXTRINSICS)
    assert expected is not None and 0.3 <= expected <= took + 0.05, (expected, took)
    # Another kind has none yet; a failed or stopped job measures nothing.
    assert journal.expected_s("calibrate", {"what": "intrinsics"}) is None
    journal.start("map", 2, {"points": True})
    journal.finish("failed", "capture_failed: no frame")
    assert journal.expected_s("map", {}) is None
    journal.start("map", 3, {})
    journal.finish("stopped", "stopped: stop")
    assert journal.expected_s("map", {}) is None
    # Carried through the other jobs, and read back by the next service on this cell.
    assert JobJournal(tmp_path).expected_s("calibrate", EXTRINSICS) == expected


def test_the_job_line_gives_the_running_time_against_the_last_run() -> None:
    # The running time is the clock's: whole seconds, which a loaded machine may push on by one.
    job = Job("calibrate", 7, State.CALIBRATING, expected_s=41.6)
    job.started -= 12.0
    line = job_text(job.describe())
    assert re.fullmatch(
        r"calibrate \(request 7\), 1[23] s of about 42 s \(its last run here\)", line
    ), line
    first = job_text(Job("map", 8, State.MAPPING).describe())
    assert re.fullmatch(r"map \(request 8\), [01] s", first), first
