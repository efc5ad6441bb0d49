"""The one-screen reading of a job's reply (`omnisort ctl map`, `calibrate`, `sort`, ...):
its verdict first, then its top-level figures and files; `--json` gives the whole reply. A
reply of any shape reads: a part the reply does not have is left out."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from omnisort_hw.pipeline.verdict import verdict_lines, verdict_of

MAX_FIELDS = 12


def _scalar(value: object) -> bool:
    return isinstance(value, str | int | float | bool) or value is None


def summarise_reply(command: str, result: Mapping[str, Any]) -> str:
    """The reply's verdict, its scalar top-level fields (paths, counts, figures), a sort's
    totals, and where the rest is."""
    lines: list[str] = []
    verdict = verdict_of(result)
    if verdict is not None:
        lines += verdict_lines(verdict)
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


def _argument_line(name: str, prop: Mapping[str, Any], required: bool) -> str:
    """`  square_mm  number 1..1000 mm (optional): board square size` from its JSON Schema."""
    value = prop if required else (prop.get("anyOf") or [prop])[0]
    kind = str(prop.get("x-kind", value.get("type", "")))
    parts = [kind]
    if "enum" in value:
        parts = ["|".join(str(v) for v in value["enum"])]
    if "minimum" in value or "maximum" in value:
        parts.append(f"{value.get('minimum', '')}..{value.get('maximum', '')}")
    if prop.get("x-unit"):
        parts.append(str(prop["x-unit"]))
    if "default" in prop:
        parts.append(f"default {json.dumps(prop['default'])}")
    elif not required:
        parts.append("optional")
    return f"    {name}  {' '.join(parts)}: {prop.get('description', '')}"


def summarise_describe(result: Mapping[str, Any]) -> str:
    """`omnisort ctl describe`: each command, how it runs, and its arguments (from their JSON
    Schema, the one every client builds its forms from)."""
    lines: list[str] = []
    for name, command in result.get("commands", {}).items():
        token = "" if command.get("needs_token") else ", no token"
        lines.append(f"{name} ({command.get('kind')}{token}): {command.get('help', '')}")
        schema = command.get("args", {})
        required = set(schema.get("required", ()))
        for arg, prop in schema.get("properties", {}).items():
            lines.append(_argument_line(arg, prop, arg in required))
    lines.append("(each command's JSON Schema: --json)")
    return "\n".join(lines)
