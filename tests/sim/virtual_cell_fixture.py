"""The virtual cell as a subprocess fixture: own loopback address, readiness probe (`ready
HOST` once every port accepts), ordered teardown (SIGTERM, wait, then kill)."""

from __future__ import annotations

import json
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from sim_backend.virtual_cell.launcher import VirtualCellError, VirtualCellProcess


@contextmanager
def virtual_cell(
    scene: str = "sorting", width: int = 256, **kw: object
) -> Iterator[VirtualCellProcess]:
    vc = VirtualCellProcess(scene, width=width, **kw)  # type: ignore[arg-type]
    try:
        vc.start()
    except VirtualCellError as exc:
        pytest.fail(f"virtual cell did not start: {exc}")
    try:
        yield vc
    finally:
        code = vc.stop()
        assert code in (0, None, -9), f"virtual cell exited with {code}: {vc.log_tail()}"


def streamed_frame(host: str) -> np.ndarray:
    """One lossless frame of the virtual cell's camera as it streams (the world as it is now)."""
    with urllib.request.urlopen(f"http://{host}:8080/frame.png", timeout=60) as r:
        return np.asarray(cv2.imdecode(np.frombuffer(r.read(), np.uint8), cv2.IMREAD_COLOR))


def run_client(module: str, *args: str, timeout_s: float = 90.0) -> Any:
    """Run a client module (`python -m MODULE ARGS`) in its own process, bounded by
    `timeout_s`; the JSON object on its last line of output."""
    run = subprocess.run(
        [sys.executable, "-m", module, *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        cwd=Path(__file__).resolve().parents[2],
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])
