"""The one-screen reading of a job's reply (`omnisort ctl map`, `calibrate`, `sort`, ...):
its verdict first, then its top-level figures and files; `--json` gives the whole reply. A
reply of any shape reads: a part the reply does not have is left out."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from omnisort_hw.pipeline.verdict import verdict_lines

MAX_FIELDS = 12


def _scalar(value: Any) -> bool:
    return isinstance(value, str | int | float | bool) or value is None


def summarise_reply(command: str, result: Mapping[str, Any]) -> str:
    """The reply's verdict, its scalar top-level fields (paths, counts, figures), a sort's
    totals, and where the rest is."""
    lines: list[str] = []
    if isinstance(result.get("verdict"), Mapping):
        lines += verdict_lines(result["verdict"])
    else:
        lines.append(f"{command}: done")
    shown = 0
    for key, value in result.items():
        if key == "verdict" or not _scalar(value) or value is None:
            continue
        if shown == MAX_FIELDS:
            break
        lines.append(f"{key}: {value}")
        shown += 1
    totals = result.get("totals")
    if isinstance(totals, Mapping):
        lines.append("totals: " + ", ".join(f"{k} {v}" for k, v in totals.items() if _scalar(v)))
    lines.append("(the whole reply: --json)")
    return "\n".join(lines)
