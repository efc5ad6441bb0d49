"""Verdicts: the worst check decides, each check says its figure and threshold, and a
non-pass says what to do; the same lines reach every door."""

from __future__ import annotations

from omnisort_hw.pipeline.verdict import (
    Check,
    Verdict,
    at_least,
    graded,
    verdict_lines,
    verdict_of,
)
from omnisort_hw.wire_records import to_wire


def test_a_graded_figure_passes_warns_and_fails_at_its_thresholds() -> None:
    assert graded("rms", 0.5, "px", 0.5, 1.0).level == "pass"  # the threshold itself passes
    warn = graded("rms", 0.7, "px", 0.5, 1.0, advice="look again")
    assert warn.level == "warn" and warn.advice == "look again"
    assert graded("rms", 1.01, "px", 0.5, 1.0).level == "fail"
    assert graded("rms", 9.0, "px", 0.5).level == "warn"  # no fail threshold: warn at most
    assert graded("rms", 0.2, "px", 0.5, 1.0, advice="unused").advice == ""
    assert graded("rms", float("nan"), "px", 0.5, 1.0).level == "fail"  # NaN is no pass


def test_the_worst_check_is_the_verdict_and_every_line_says_why() -> None:
    checks = (
        graded("rms", 0.2, "px", 0.5, 1.0),
        at_least("segments", 0, 1, "warn", "is the laser on?"),
    )
    v = Verdict("laser map", checks)
    assert v.level == "warn"
    lines = verdict_lines(v)
    assert verdict_lines(verdict_of({"verdict": to_wire(v)})) == lines  # as a reply sends it
    assert "advice" not in to_wire(checks[0])  # a pass says nothing to do: its key is left out
    assert lines[0] == "WARN: laser map"
    assert "segments: 0 (>= 1); is the laser on?" in lines[2]
    assert "rms: 0.2 px (pass <= 0.5 px, fail > 1 px)" in lines[1]
    fail = Verdict("x", (*checks, Check("turn", "fail", "1 deg", "< 0.02 deg", "stop")))
    assert fail.level == "fail" and Verdict("none", ()).level == "pass"
