"""The guided step's level of a job's end: its verdict's, a FAIL for a job that failed or was
refused, and a FAIL for a verdict it cannot read (never a way on by accident). The buttons
each level shows are tested in the browser (test_browser_recovery, the commissioned cell)."""

from __future__ import annotations

from typing import Any

import pytest

from omnisort_hw.pipeline.verdict import Verdict, graded, verdict_of
from omnisort_hw.ui.guided_step import level_of, verdict_text
from omnisort_hw.ui.job_runner import JobEnd
from omnisort_hw.wire_records import to_wire


def end(ok: bool, result: dict[str, Any] | None) -> JobEnd:
    return JobEnd("calibrate", ok, "calibrate: capture_failed: no frame", result, 0.0)


@pytest.mark.parametrize(("value", "level"), [(0.1, "pass"), (0.5, "warn"), (2.0, "fail")])
def test_the_level_is_the_verdicts(value: float, level: str) -> None:
    verdict = Verdict("extrinsics", (graded("sigma", value, "mm", 0.2, 1.0, advice="retake"),))
    result = {"verdict": to_wire(verdict)}
    assert level_of(end(True, result)) == level
    text = verdict_text(verdict_of(result))
    assert text.startswith(f"{level.upper()}: extrinsics"), text
    assert ("retake" in text) == (level != "pass"), text


def test_a_failed_job_or_an_unreadable_verdict_is_a_fail() -> None:
    assert level_of(end(False, None)) == "fail"
    assert level_of(end(True, None)) == "fail"
    assert level_of(end(True, {"verdict": {"level": "ok?"}})) == "fail"
    assert level_of(end(True, {"done": True})) == "pass"  # a reply that judges nothing
    assert verdict_text(verdict_of({"done": True})) == ""
