"""The sort cycle's images from a measurement capture (`measurement_capture`): the board
image (laser off, N frames averaged at the board exposure) for the cubes' colours and the
laser-light image (on/off difference at the stripe exposure) for their heights, recorded.

Used by the cell's `sort` when its camera and laser are configured and `[sorting].use_laser`
is on; `[capture].differencing = false` keeps the single frames as before.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from omnisort_hw.pipeline.cell_acquisition import acquire


def cell_sort_capture(cell: Any) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """(colour image, laser-light image, the capture's record) from `cell` (a `Cell`); the
    laser is left off, as the sort's single frames left it (the cubes' colours, the next
    capture and the operator's eyes expect it off)."""
    try:
        acq = acquire(cell, None, board=True)
    finally:
        cell.set_laser(False)
    return acq.board, acq.stripe, acq.record


def sort_capture_for(
    cell: Any,
) -> Callable[[], tuple[np.ndarray, np.ndarray | None, dict[str, Any]]] | None:
    """The capture the cell's sort uses, or None (single frames) without a laser or with
    `[capture].differencing = false`."""
    if cell.devices.laser is None or not cell.capture_settings.differencing:
        return None
    return lambda: cell_sort_capture(cell)
