"""No measured figure in README.md or docs/*.md is typed by hand.

The rule (`benchmarks/prose.py`): a figure is a number followed by a unit (ms, s, min, h, px,
mm, m, deg, °, %, Hz, MB, ...) or a rate (/min, /s, per minute, per pick, picks per minute,
fps, frames per second). It counts as measured when its sentence holds a measurement word
(measured, took, timed, found, median, mean, max, worst, largest, RMS, MAE, error, latency,
grew, σ, std, p95, p99, faster, slower, off by, ...), a result verb with a number right after
it (takes 0.6 s, gives 0.170 %, came out at 70 mm, drops to, is at, ...), a change by a number
(moved/shifted/changed ... by 0.1 mm) or "within 0.002 px of"; a sentence ends at `.`, `!` or
`?`, not at `;`; a table row is read with its header row and a code block as one sentence.
Outside the generated regions (`<!-- figures:NAME -->` blocks and
`<!-- fig:PATH|FMT -->` inline figures, both rendered from `benchmarks/results.json`) every
measured figure fails this test unless `docs/figures_allowlist.txt` excuses it: the text around
it and why it is not a measurement of this code (setting, tolerance, published, input, history).
A measurement of this code that no bench records has no excuse: an entry whose reason is
`unrecorded` fails, so such a figure is recorded by a bench and generated, or the sentence is
told without it. An entry that no longer excuses anything fails too, so the list cannot outlive
its sentences.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import figures, prose

ROOT = Path(__file__).resolve().parents[1]


def test_every_measured_figure_is_generated_or_excused() -> None:
    bare, _ = prose.check(list(figures.DOCUMENTS), ROOT, prose.load_allowlist(figures.ALLOWLIST))
    assert not bare, (
        "measured figures typed by hand (generate them with <!-- fig:PATH|FMT -->):\n"
        + ("\n".join(map(str, bare)))
    )


def test_every_allowlist_entry_still_excuses_a_figure() -> None:
    _, unused = prose.check(list(figures.DOCUMENTS), ROOT, prose.load_allowlist(figures.ALLOWLIST))
    assert not unused, "stale entries in docs/figures_allowlist.txt:\n" + "\n".join(
        f"{e.path} | {e.text}" for e in unused
    )


def test_a_hand_typed_measurement_is_caught(tmp_path: Path) -> None:
    """The lint can fail: the sentence that went stale in virtual_cell.md, typed again."""
    doc = tmp_path / "doc.md"
    doc.write_text(
        "Intro at 960 px.\n\nThe stream costs the stripe (p95 5.7 px at quality 95).\n\n"
        "| case | median |\n| --- | --- |\n| idle | 0.7 ms |\n\n"
        "    calibrate intrinsics    5.2 s  rms 0.016 px\n",
        encoding="utf-8",
    )
    hits = prose.measured_figures(doc, tmp_path)
    assert [h.figure for h in hits] == ["5.7 px", "0.7 ms", "5.2 s", "0.016 px"]
    excuse = prose.Entry("doc.md", "p95 5.7 px", "history: test")
    bare, unused = prose.check([doc], tmp_path, [excuse])
    assert len(bare) == 3 and unused == []


def test_generated_figures_are_not_hits(tmp_path: Path) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text(
        "The p95 is <!-- fig:virtual_cell/stripe_q95_p95_px|.3f -->0.742<!-- /fig --> px.\n\n"
        "<!-- figures:soak -->\n| soak | measured |\n| length | 10 min |\n<!-- /figures -->\n",
        encoding="utf-8",
    )
    assert prose.measured_figures(doc, tmp_path) == []


def test_inline_figures_follow_the_record() -> None:
    results = figures.load_results()
    text = "p95 <!-- fig:virtual_cell/stripe_q95_p95_px|.2f -->9<!-- /fig --> px"
    assert figures.render(text, results) == (
        f"p95 <!-- fig:virtual_cell/stripe_q95_p95_px|.2f -->"
        f"{results['virtual_cell']['stripe_q95_p95_px']:.2f}<!-- /fig --> px"
    )
    results["virtual_cell"]["stripe_q95_p95_px"] = 5.7
    assert "5.70<!-- /fig -->" in figures.render(text, results)
    with pytest.raises(KeyError, match="no_such_key"):
        figures.render("<!-- fig:virtual_cell/no_such_key -->1<!-- /fig -->", results)


def test_keys_with_dots_and_list_indices() -> None:
    results = {"service": {"during_sort.long_command_s": 11.72, "load": [0.1, 1.4]}}
    assert prose.lookup(results, "service/during_sort.long_command_s") == 11.72
    assert prose.lookup(results, "service/load/1") == 1.4


def test_an_allowlist_entry_needs_a_known_reason(tmp_path: Path) -> None:
    bad = tmp_path / "allow.txt"
    bad.write_text("docs/x.md | 5 s | because\n", encoding="utf-8")
    with pytest.raises(ValueError, match="reason"):
        prose.load_allowlist(bad)


def test_an_unrecorded_figure_is_not_excused(tmp_path: Path) -> None:
    """The debt cannot come back: `unrecorded` is no reason, whatever follows it."""
    for reason in ("unrecorded: a diagnostic run, not in results.json", "unrecorded"):
        allow = tmp_path / "allow.txt"
        allow.write_text(f"docs/x.md | took 5 s | {reason}\n", encoding="utf-8")
        with pytest.raises(ValueError, match="record it in a bench"):
            prose.load_allowlist(allow)


def test_the_allowlist_has_no_unrecorded_entry() -> None:
    entries = prose.load_allowlist(figures.ALLOWLIST)
    assert entries and all(e.reason.split(":", 1)[0] in prose.REASONS for e in entries)


@pytest.mark.parametrize(
    ("sentence", "figure"),
    [
        # rates are figures
        ("The pick cycle reached 9.36 picks per minute on the seed.", "9.36 picks per minute"),
        ("The stream measured 10 fps at 960 px.", "10 fps"),
        ("The truth run gave 9.47/min.", "9.47/min"),
        # a result verb right before the number
        ("A frame with the laser takes 0.6-0.8 s on one core.", "0.6-0.8 s"),
        ("The stripe centre comes out at 0.01-0.03 px from the truth.", "0.01-0.03 px"),
        ("Measuring in light moved the laser distance by 0.1-0.3 mm only.", "0.1-0.3 mm"),
        ("The edge lands within 0.002 px of a linear camera's edge.", "0.002 px"),
        # `;` no longer ends the sentence the measurement word is in
        ("The median stays put (clean 0.01 px; degraded 0.4 px in the same run).", "0.4 px"),
    ],
)
def test_the_closed_gaps_are_caught(tmp_path: Path, sentence: str, figure: str) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text(sentence + "\n", encoding="utf-8")
    assert figure in [h.figure for h in prose.measured_figures(doc, tmp_path)]
    bare, _ = prose.check([doc], tmp_path, [])
    assert bare


def test_a_setting_sentence_still_passes(tmp_path: Path) -> None:
    """Units alone, or a result verb without a number after it, are no measurement."""
    doc = tmp_path / "doc.md"
    doc.write_text(
        "The camera renders 1920 px images of a 40 mm board square; the arm moves at 300 mm/s.\n\n"
        "The check takes a cube away and gives the laser plane a 1 m lever; it drops the oldest"
        " data beyond 256 MiB.\n\nThe covariance Σ of 64 blocks of 30 px is the test's input.\n",
        encoding="utf-8",
    )
    assert prose.measured_figures(doc, tmp_path) == []
