"""The command table of docs/service.md is the one the commands' declaration writes."""

from __future__ import annotations

from pathlib import Path

from omnisort_hw.service.command_table import command_table, with_table
from omnisort_hw.service.protocol import COMMANDS

DOC = Path(__file__).resolve().parents[2] / "docs" / "service.md"


def test_the_documented_table_is_the_declared_one() -> None:
    text = DOC.read_text(encoding="utf-8")
    assert with_table(text) == text, (
        "docs/service.md's command table differs from the declaration: "
        "python -m omnisort_hw.service.command_table docs/service.md"
    )


def test_the_table_has_a_row_per_command_and_escapes_choices() -> None:
    rows = command_table().splitlines()[2:]
    assert [r.split("`")[1] for r in rows] == list(COMMANDS)
    assert all(r.count(" | ") == 4 for r in rows)  # a choice's | did not split a cell
