"""The protocol's command table in `docs/service.md`, written from the commands' declaration
(`protocol.COMMANDS` and their request records), never by hand:

    python -m omnisort_hw.service.command_table docs/service.md

rewrites the table between its markers; `tests/service/test_command_table.py` fails when the
table and the declaration differ.
"""

from __future__ import annotations

import sys
from pathlib import Path

from omnisort_hw.request_fields import Arg, condition_text
from omnisort_hw.service.protocol import COMMANDS, Command

BEGIN = "<!-- commands: written by python -m omnisort_hw.service.command_table -->"
END = "<!-- /commands -->"


def _arg_text(arg: Arg) -> str:
    shape = "|".join(arg.choices) if arg.choices else arg.kind
    if arg.length:
        shape += f"[{arg.length}]"
    if arg.lo is not None or arg.hi is not None:
        shape += " " + "..".join("" if b is None else f"{b:g}" for b in (arg.lo, arg.hi))
    if arg.unit:
        shape += f" {arg.unit}"
    notes = []
    if arg.required:
        notes.append("required")
    elif arg.default not in (None, False):
        notes.append(f"default {arg.default}")
    if arg.required_when:
        notes.append("required " + " and ".join(condition_text(c) for c in arg.required_when))
    if arg.only_when:
        notes.append("only " + " and ".join(condition_text(c) for c in arg.only_when))
    tail = f" ({', '.join(notes)})" if notes else ""
    return f"`{arg.name}` {shape}{tail}: {arg.help}"


def _row(command: Command) -> str:
    args = "<br>".join(_arg_text(a) for a in command.args) or "none"
    token = "yes" if command.needs_token else "never"
    runs = f"{command.kind} ({command.job_state})" if command.job_state else command.kind
    cells = (f"`{command.name}`", command.summary, args, runs, token)
    return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"


def command_table() -> str:
    """The markdown table of every command: what it does, its arguments, how it runs."""
    lines = [
        "| command | does | args | runs as | token |",
        "| --- | --- | --- | --- | --- |",
        *(_row(c) for c in COMMANDS.values()),
    ]
    return "\n".join(lines)


def with_table(text: str) -> str:
    """`text` with the table between its markers replaced by the current one."""
    start, end = text.index(BEGIN) + len(BEGIN), text.index(END)
    return text[:start] + "\n" + command_table() + "\n" + text[end:]


def main(argv: list[str]) -> int:
    for name in argv:
        path = Path(name)
        path.write_text(with_table(path.read_text(encoding="utf-8")), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
