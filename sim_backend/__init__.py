"""The simulated robot cell on pybullet: scenes, fisheye and laser rendering with ground truth,
datasets, and simulated devices behind the `drivers.base` interfaces.

Entry points: `sim_backend.scene_images` (render_scene, write_render), `sim_backend.dataset`
(make_dataset, checkerboard_views), `sim_backend.devices` (SimCell, SimCamera, SimLaserSwitch,
SimArm, open_devices).
"""

from __future__ import annotations

import ctypes
import os
import sys


def _import_pybullet_quietly() -> None:
    """Import pybullet with its "build time" banner sent to stderr, not stdout.

    The banner is printed by the C extension (stdio-buffered), so stdout's descriptor is pointed
    at stderr and C's buffers are flushed before it is restored; commands that print JSON on
    stdout stay parseable.
    """
    if "pybullet" in sys.modules:
        return
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):
        import pybullet

        return
    try:
        os.dup2(2, 1)
        import pybullet  # noqa: F401

        ctypes.CDLL(None).fflush(None)
    finally:
        os.dup2(saved, 1)
        os.close(saved)


_import_pybullet_quietly()
