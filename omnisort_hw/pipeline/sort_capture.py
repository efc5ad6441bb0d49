"""The sort cycle's images from a measurement capture (`measurement_capture`): the board
image (laser off, N frames averaged at the board exposure) for the cubes' colours and the
laser-light image (on/off difference at the stripe exposure) for their heights, recorded.

Used by every sort (`pipeline.sort_run`) when the rig's camera and laser are configured and
`[sorting].use_laser` is on; `[capture].differencing = false` keeps the single frames as before.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from omnisort_hw.pipeline.cell_acquisition import CaptureRig, acquire


def sort_capture(
    rig: CaptureRig, laser_off: Callable[[], object]
) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    """(colour image, laser-light image, the capture's record) from `rig`; the laser is left
    off (`laser_off`), as the sort's single frames left it (the cubes' colours, the next
    capture and the operator's eyes expect it off)."""
    try:
        acq = acquire(rig, None, board=True)
    finally:
        laser_off()
    return acq.board, acq.stripe, acq.record


def sort_capture_for(
    rig: CaptureRig, laser_off: Callable[[], object] | None
) -> Callable[[], tuple[np.ndarray, np.ndarray | None, dict[str, Any]]] | None:
    """The capture a sort on `rig` uses, or None (single frames) without a laser (no
    `laser_off`) or with `[capture].differencing = false`."""
    if laser_off is None or not rig.capture_settings.differencing:
        return None
    return lambda: sort_capture(rig, laser_off)
