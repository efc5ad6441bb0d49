"""The check capture between picks knows every pose the arm went through while its frame was
taken: the frame shows the arm at one instant of the grab, which the camera does not report, so
a box the arm covered at that instant is `hidden`, not `changed` (a cube judged on a frame where
the arm half covers it was located again with a 20 mm fit and skipped)."""

from __future__ import annotations

import threading

import numpy as np

from omnisort_hw.pipeline.scene_check import MAX_STEP_DEG, ChangeWatch, swept_joints

Q0 = np.array([0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
Q1 = np.array([120.0, -60.0, 40.0, -70.0, -90.0, 45.0])
READS = 40  # the arm goes from Q0 to Q1 over this many reads of its joints (3 deg per read)
SHOWN_AT = 10.5  # the frame shows the arm between its 10th and 11th read
GRAB_READS = 20  # the grab ends once the arm has been read this often
WAIT_S = 30.0  # hang guard


def test_swept_joints_fill_in_every_step_and_drop_repeats() -> None:
    qs = swept_joints([Q0, Q0, Q1, Q1])
    steps = np.abs(np.diff(np.asarray(qs), axis=0)).max(axis=1)
    assert np.all(steps > 0) and np.all(steps <= MAX_STEP_DEG + 1e-9)
    assert np.array_equal(qs[0], Q0) and np.allclose(qs[-1], Q1)
    assert len(qs) == 1 + int(np.ceil(np.abs(Q1 - Q0).max() / MAX_STEP_DEG))
    assert swept_joints([]) == [] and len(swept_joints([Q0])) == 1


def _pose(reads: float) -> np.ndarray:
    return Q0 + min(1.0, reads / READS) * (Q1 - Q0)


class _MovingArm:
    """An arm on its way from Q0 to Q1, one step further at each read of its joints (so the
    test follows the reads, not the clock)."""

    def __init__(self) -> None:
        self.reads = 0
        self.lock = threading.Lock()
        self.read_enough = threading.Event()

    def joint_positions(self) -> np.ndarray:
        with self.lock:
            self.reads += 1
            if self.reads >= GRAB_READS:
                self.read_enough.set()
            return _pose(self.reads)


class _Frame:
    image = np.zeros((8, 8, 3), np.uint8)


class _Camera:
    """A camera whose frame shows the arm at SHOWN_AT reads, and whose grab lasts until the
    arm has been read GRAB_READS times."""

    def __init__(self, arm: _MovingArm) -> None:
        self.arm = arm

    def grab(self) -> _Frame:
        assert self.arm.read_enough.wait(WAIT_S), "the joints were not read during the grab"
        return _Frame()


class _Cfg:
    class colors:  # noqa: N801 - the colour table's one method the capture calls
        @staticmethod
        def masks(img: np.ndarray) -> tuple[dict[str, np.ndarray], None]:
            return {"red": np.zeros(img.shape[:2], np.uint8)}, None


class _Check:
    cfg = _Cfg()


def test_the_check_capture_holds_the_pose_its_frame_shows() -> None:
    arm = _MovingArm()
    watch = ChangeWatch(_Check(), _Camera(arm), arm, list, None, None)  # type: ignore[arg-type]
    try:
        _, qs, masks = watch._capture()
    finally:
        watch.close()
    assert set(masks) == {"red"}
    shown = _pose(SHOWN_AT)
    # The pose the frame shows lies between two reads of the joints (3 deg apart): the
    # filled-in poses hold it within half a step.
    nearest = min(float(np.abs(q - shown).max()) for q in qs)
    assert nearest <= MAX_STEP_DEG / 2 + 1e-9, nearest
    # The ends of the grab alone, as the check had them, miss it by tens of degrees.
    assert min(float(np.abs(q - shown).max()) for q in (qs[0], qs[-1])) > 10 * MAX_STEP_DEG


OBLIQUE = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, 0.3]])  # (x, y, z) mm -> "pixels"


class _Flat:
    """A camera model that images points by a parallel oblique projection: enough to compare
    points, and no arm axis is along its direction."""

    @staticmethod
    def ray_to_pixel(p: np.ndarray) -> np.ndarray:
        return np.asarray(p, float) @ OBLIQUE


class _Calib:
    model = _Flat()
    R_SC = np.eye(3)


def test_the_cube_the_arm_carries_is_part_of_what_it_covers() -> None:
    """The check frame is taken while the picked cube is carried: its pixels are the arm's, so
    its blob is neither a cube put down nor a reason to judge a box."""
    from omnisort_hw.core.kinematics import joint_frames
    from omnisort_hw.core.pick_planning import Planner
    from omnisort_hw.pipeline.scene_check import arm_pixels
    from sim_backend.sort_harness import sim_sort_config
    from tests.pipeline.sorting_scene import sorting_scene

    scene = sorting_scene()
    planner = Planner(sim_sort_config(scene), np.eye(4))
    px = arm_pixels(planner, _Calib(), np.eye(4), [Q1])  # type: ignore[arg-type]
    held = planner.held
    flange = joint_frames(planner.model, Q1)[held.frame]
    centre = flange[:3, :3] @ np.asarray(held.start_mm) + flange[:3, 3]
    below = centre + flange[:3, :3] @ [0.0, 0.0, held.radius_mm]  # the cube's far side
    for point in (centre, below):
        assert float(np.min(np.linalg.norm(px - point @ OBLIQUE, axis=1))) < 1e-6, point
