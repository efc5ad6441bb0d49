"""`omnisort ... --json` run as a user runs it (a subprocess), its result read back."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any


def cli_result(*args: str, ok_codes: tuple[int, ...] = (0,), timeout_s: float = 600) -> Any:
    """The `result` of `omnisort ARGS --json`; the exit code must be one of `ok_codes`."""
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", *args, "--json"],
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert proc.returncode in ok_codes, proc.stderr + proc.stdout
    reply = json.loads(proc.stdout)
    assert reply["ok"], reply
    return reply["result"]
