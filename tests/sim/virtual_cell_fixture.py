"""The virtual cell as a subprocess fixture: own loopback address, readiness probe (`ready
HOST` once every port accepts), ordered teardown (SIGTERM, wait, then kill)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

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
