"""The tables of measured figures in README.md and docs/ are the record's
(`benchmarks/results.json`), regenerated here and compared; README stays short and opens with
the two commands; no file cites the old out-of-tree design notes."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks import figures

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("path", figures.DOCUMENTS, ids=lambda p: p.name)
def test_every_figures_block_matches_results_json(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    assert figures.render(text, figures.load_results()) == text, (
        f"{path.name}: a figures block differs from benchmarks/results.json; "
        "run python -m benchmarks.figures --write"
    )


def test_the_blocks_are_where_the_figures_are() -> None:
    found = {name for p in figures.DOCUMENTS for name in figures.blocks(p.read_text())}
    assert found == set(figures.GENERATORS)
    assert "summary" in figures.blocks((ROOT / "README.md").read_text())


def test_a_changed_record_changes_the_tables() -> None:
    """The check can fail: one figure changed in the record shows up in the README block."""
    results = figures.load_results()
    readme = (ROOT / "README.md").read_text()
    results["sorting"]["truth_sorted_ok"] = -1
    assert figures.render(readme, results) != readme


def test_readme_is_short_and_opens_with_the_two_commands() -> None:
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 200
    first = [line.strip() for line in lines[1:6] if line.strip()]
    assert first[0].startswith("make demo") and first[1].startswith("make test")
    assert (ROOT / "docs" / "images" / "demo.png").is_file()


# What the project's tools make (the type check writes its cache while the tests run).
OUT_OF_TREE = {".venv", ".git", "build", ".mypy_cache", ".pytest_cache", ".ruff_cache"}


def test_no_file_cites_the_out_of_tree_design_notes() -> None:
    needle = "../shared/" + "design"
    hits = [
        str(p.relative_to(ROOT))
        for p in ROOT.rglob("*")
        if not OUT_OF_TREE & set(p.relative_to(ROOT).parts)
        and p.suffix in {".py", ".md", ".toml", ".txt", ".cfg", ".sh", ".service"}
        and p.is_file()
        and needle in p.read_text(encoding="utf-8", errors="replace")
    ]
    assert hits == []
    assert (ROOT / "docs" / "frames.md").is_file()
