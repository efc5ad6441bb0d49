"""The board held in front of the virtual cell's fisheye for its intrinsic views.

A person calibrating a real lens walks a checkerboard through the camera's field of view; the
virtual cell stands in for that with a set of HELD_VIEWS board poses covering the field ring by
ring (`sim_backend.dataset.screen_views`, the demo's calibration views). While a board is held
(`{"cmd": "board", "view": k}` on the control channel) the camera shows the published
simulator's calibration screen with that board, through the cell's own lens; `"view": null`
puts the cell back in the picture. Intrinsics are the lens's alone, so the views need not show
the cell.
"""

from __future__ import annotations

import functools

from omnisort_hw.sim_requests import HELD_VIEWS
from sim_backend.dataset import calibration_screen_scene, screen_views
from sim_backend.scene import Scene

__all__ = ["HELD_VIEWS", "check_view", "held_board_scene"]
HELD_SEED = 1
HELD_BOARD = (9, 6)  # inner corners
HELD_SQUARE_MM = 116.0


def check_view(view: object) -> int | None:
    """`view` as a pose index of the set, or None (no board held); ValueError otherwise."""
    if view is None:
        return None
    if isinstance(view, bool) or not isinstance(view, int) or not 0 <= view < HELD_VIEWS:
        raise ValueError(f"view must be a pose 0..{HELD_VIEWS - 1} or null, got {view!r}")
    return view


@functools.lru_cache(maxsize=4)
def _views(width: int, height: int, fov_deg: float, circle_deg: float, model: str) -> list[Scene]:
    base = calibration_screen_scene(width, model).replace(
        camera={"height": height, "fov_deg": fov_deg, "image_circle_fov_deg": circle_deg}
    )
    return screen_views(base, HELD_VIEWS, HELD_SEED, HELD_BOARD, HELD_SQUARE_MM)


def held_board_scene(cell_scene: Scene, view: int) -> Scene:
    """The calibration screen with the board at pose `view`, seen through `cell_scene`'s
    camera (its size, field of view and model file)."""
    if check_view(view) is None:
        raise ValueError("held_board_scene needs a pose, not None (no board held)")
    cam = cell_scene.camera
    scenes = _views(cam.width, cam.height, cam.fov_deg, cam.image_circle_fov_deg, cam.model_file)
    return scenes[view]
