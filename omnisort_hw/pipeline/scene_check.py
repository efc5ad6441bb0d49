"""Change checks between picks: what changed since the one capture that located every cube.

The sort locates every cube once, from a capture taken with the arm parked out of view. Once
each picked cube is lifted, a check capture is taken (it overlaps the carry to the bin) and
compared with that first image only where it matters: each cube still to pick is looked for
in its blob's box, by its colour. A cube still covering its box is left as it is, without a
new location. A cube that no longer does was knocked or taken away: the check image is
located again (in the compute worker) and the cube is matched to a cube of its colour near
where it was; it is `moved` (its new pose replaces the old) or `gone` (removed by hand: it is
neither picked nor an obstacle any more). A box the arm covers in the check image cannot be
judged: the cube is `hidden` and judged at the next check.

A cube put down after the first capture is found the same way, without a full location: the
check image's colour pixels that the first image did not have (per colour, a few pixels of
slack) form blobs, and a blob that could be a cube (the location's own region, exclusions and
area rule) and that the arm does not cover has the image located again; a located cube that
matches no known cube is `added` (to pick if its colour is requested, an obstacle anyway).
Every blob judged is then part of the reference, so it is judged once.

How much of its box a cube must still cover follows from the gripper: a cube shifted by half
the gripper's margin on each side (margin = (stroke - size) / 2) still grasps; such a shift
leaves a fraction 1 - margin / (2 size) of the box covered.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.collision import arm_capsules
from omnisort_hw.core.cube_location import Cube, FloorGeometry, LocateSettings, blob_verdict
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.kinematics import joint_frames
from omnisort_hw.core.pick_planning import Planner, SortConfig

# Pixels around a cube's box that count as covered when an arm point lands there.
ARM_MARGIN_PX = 6
# The longest a check capture may take (a camera frame; the simulated one renders).
CAPTURE_TIMEOUT_S = 60.0
# Points per capsule axis (and its radius offsets) projected to find what the arm covers.
ARM_SAMPLES = 12
# The arm's joints are read this often while a check frame is taken: the frame shows the arm
# at some instant of the grab, unknown to the camera, so every pose it went through counts.
JOINT_SAMPLE_S = 0.005
# Poses between two reads are filled in, joint-space linear, so that no joint turns more than
# this between two poses: 1 deg moves a point 1 m from the base by 17 mm, under half the
# thinnest capsule's diameter (the wrist's, 2 x 35 mm on a UR3e), so the poses' union covers
# what the arm swept.
MAX_STEP_DEG = 1.0
# Slack (px) within which a colour pixel of a check image counts as seen in the first one, and
# the smallest new blob looked at (the location's own smallest blob).
SEEN_SLACK_PX = 4
MIN_BLOB_PX = 30
_SEEN_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * SEEN_SLACK_PX + 1,) * 2)
_KERNEL3 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))


@dataclass
class CheckResult:
    """What one check found, per cube index."""

    still: list[int] = field(default_factory=list)
    hidden: list[int] = field(default_factory=list)
    moved: dict[int, Cube] = field(default_factory=dict)
    gone: list[int] = field(default_factory=list)
    added: list[Cube] = field(default_factory=list)
    located_again: bool = False  # the image was located again (a change or a new blob)
    covered: dict[int, float] = field(default_factory=dict)  # fraction of the box still covered

    @property
    def changed(self) -> bool:
        return bool(self.moved or self.gone or self.added)

    def summary(self) -> dict[str, Any]:
        return {
            "still": self.still,
            "hidden": self.hidden,
            "moved": sorted(self.moved),
            "gone": self.gone,
            "added": [c.color for c in self.added],
            "located_again": self.located_again,
            "covered": {k: round(v, 3) for k, v in self.covered.items()},
        }


def keep_fraction(cfg: SortConfig) -> float:
    """The fraction of its box a cube that has not moved enough to matter still covers."""
    margin = max(0.0, cfg.gripper_stroke_mm - cfg.cube_size_mm) / 2.0
    return 1.0 - margin / (2.0 * cfg.cube_size_mm)


def _crop(img: np.ndarray, bbox: tuple[int, int, int, int]) -> np.ndarray:
    x, y, w, h = bbox
    return img[max(0, y) : y + h, max(0, x) : x + w]


def colour_in_box(
    masks: Mapping[str, np.ndarray], color: str, bbox: tuple[int, int, int, int]
) -> np.ndarray:
    """The pixels in `bbox` of `color` (bool), from an image's colour masks (none for a colour
    the table does not have)."""
    some = next(iter(masks.values()))
    return (
        _crop(masks[color], bbox) > 0 if color in masks else np.zeros_like(_crop(some, bbox), bool)
    )


def colour_masks(cfg: SortConfig, img: np.ndarray) -> dict[str, np.ndarray]:
    """Every colour of the colour table's pixels in `img` (BGR), as 0/255 masks."""
    masks, _ = cfg.colors.masks(img)
    return dict(masks)


def _grown(mask: np.ndarray) -> np.ndarray:
    """`mask` grown by the slack within which a colour pixel counts as already seen."""
    return cv2.dilate(mask, _SEEN_KERNEL)


def arm_pixels(
    planner: Planner, calib: SystemCalibration, T_SB: np.ndarray, q_deg: Iterable[np.ndarray]
) -> np.ndarray:
    """Image points (n, 2) that the arm, its gripper and the cube it may hold cover at each of
    the joints `q_deg`: points along each capsule's axis and at its radius around it, projected.
    A check frame is taken while a picked cube is carried, and the carried cube is no new cube."""
    caps = (*arm_capsules(planner.model), *planner.gripper, planner.held)
    s = np.linspace(0.0, 1.0, ARM_SAMPLES)[:, None]
    pts_B = []
    for q in q_deg:
        frames = joint_frames(planner.model, np.asarray(q, float))
        for c in caps:
            T = frames[c.frame]
            a = T[:3, :3] @ np.asarray(c.start_mm, float) + T[:3, 3]
            b = T[:3, :3] @ np.asarray(c.end_mm, float) + T[:3, 3]
            axis = a + s * (b - a)
            offsets = np.vstack([np.zeros(3), c.radius_mm * np.vstack([np.eye(3), -np.eye(3)])])
            pts_B.append((axis[:, None, :] + offsets[None]).reshape(-1, 3))
    if not pts_B:
        return np.zeros((0, 2))
    p_B = np.vstack(pts_B)
    p_S = p_B @ T_SB[:3, :3].T + T_SB[:3, 3]
    p_C = p_S @ calib.R_SC
    return np.asarray(calib.model.ray_to_pixel(p_C), float).reshape(-1, 2)


def swept_joints(q_deg: Iterable[np.ndarray]) -> list[np.ndarray]:
    """The joints `q_deg` (n, 6) read in order, with poses filled in between consecutive reads
    (joint-space linear) so that no joint turns more than MAX_STEP_DEG between two poses; a
    read equal to the one before is dropped."""
    qs = [np.asarray(q, float) for q in q_deg]
    if not qs:
        return []
    out = [qs[0]]
    for q in qs[1:]:
        step = float(np.max(np.abs(q - out[-1])))
        if step == 0.0:
            continue
        n = int(np.ceil(step / MAX_STEP_DEG))
        t = np.linspace(0.0, 1.0, n + 1)[1:, None]
        out.extend(out[-1] + t * (q - out[-1]))
    return out


def _boxes_hit(boxes: dict[int, tuple[int, int, int, int]], px: np.ndarray) -> set[int]:
    hit = set()
    m = ARM_MARGIN_PX
    for k, (x, y, w, h) in boxes.items():
        inside = (
            (px[:, 0] >= x - m)
            & (px[:, 0] <= x + w + m)
            & (px[:, 1] >= y - m)
            & (px[:, 1] <= y + h + m)
        )
        if np.any(inside):
            hit.add(k)
    return hit


class SceneCheck:
    """The reference of every cube still to pick (its box and colour pixels in the first
    image), the colour pixels the first image had, and the comparison of a check image with
    them (see module doc)."""

    def __init__(
        self,
        cubes: list[Cube],
        image: np.ndarray,
        cfg: SortConfig,
        calib: SystemCalibration,
        T_SB: np.ndarray,
        planner: Planner,
        settings: LocateSettings | None = None,
    ) -> None:
        self.cfg = cfg
        self.calib = calib
        self.T_SB = T_SB
        self.planner = planner
        self.settings = settings or cfg.locate_settings()
        self.keep = keep_fraction(cfg)
        self.ref: dict[int, tuple[str, tuple[int, int, int, int], np.ndarray, np.ndarray]] = {}
        masks = colour_masks(cfg, image)
        for k, cube in enumerate(cubes):
            self._set_ref(k, cube, masks)
        self.seen = {c: _grown(m) for c, m in masks.items()}

    def _set_ref(self, k: int, cube: Cube, masks: Mapping[str, np.ndarray]) -> None:
        x, y, w, h = (int(v) for v in cube.bbox)
        bbox = (x, y, w, h)
        self.ref[k] = (
            cube.color,
            bbox,
            colour_in_box(masks, cube.color, bbox),
            cube.center_B.copy(),
        )

    def check(
        self,
        image: np.ndarray,
        indices: Iterable[int],
        q_deg: Iterable[np.ndarray],
        relocate: Callable[[np.ndarray], list[Cube]],
        masks: Mapping[str, np.ndarray] | None = None,
    ) -> CheckResult:
        """Compare `image` (taken with the arm at the joints `q_deg`) for the cubes `indices`,
        and look for cubes put down since; `relocate(image)` locates every cube of the image
        (called only after a change). `masks` are the image's colour masks if known."""
        out = CheckResult()
        masks = dict(masks) if masks is not None else colour_masks(self.cfg, image)
        todo = [k for k in indices if k in self.ref]
        arm_px = arm_pixels(self.planner, self.calib, self.T_SB, list(q_deg))
        covered_by_arm = _boxes_hit({k: self.ref[k][1] for k in todo}, arm_px)
        changed: list[int] = []
        for k in todo:
            if k in covered_by_arm:
                out.hidden.append(k)
                continue
            color, bbox, ref, _ = self.ref[k]
            now = colour_in_box(masks, color, bbox)
            n = int(ref.sum())
            frac = float((ref & now).sum()) / n if n else 0.0
            out.covered[k] = frac
            (out.still if frac >= self.keep else changed).append(k)
        new_boxes = self._new_blobs(masks, arm_px)
        if not changed and not new_boxes:
            return out
        found = relocate(image)
        out.located_again = True
        taken: set[int] = set()
        for k in changed:
            color, _, _, c_B = self.ref[k]
            best, best_d = None, 2.0 * self.cfg.cube_size_mm
            for j, cube in enumerate(found):
                d = float(np.linalg.norm(cube.center_B[:2] - c_B[:2]))
                if cube.color == color and j not in taken and d < best_d:
                    best, best_d = j, d
            if best is not None:
                taken.add(best)
                out.moved[k] = found[best]
                self._set_ref(k, found[best], masks)
            else:
                out.gone.append(k)
                del self.ref[k]
        out.added = [
            cube
            for j, cube in enumerate(found)
            if j not in taken and self._is_new(cube, new_boxes, arm_px)
        ]
        for c, (x, y, w, h) in new_boxes.values():  # a blob judged is judged once
            self.seen[c][y : y + h, x : x + w] |= _grown(_crop(masks[c], (x, y, w, h)))
        return out

    def add(self, k: int, cube: Cube, masks: Mapping[str, np.ndarray]) -> None:
        """Keep cube `k` (an added one) in the reference (`masks`: its image's colours)."""
        self._set_ref(k, cube, masks)

    def _new_blobs(
        self, masks: Mapping[str, np.ndarray], arm_px: np.ndarray
    ) -> dict[int, tuple[str, tuple[int, int, int, int]]]:
        """Colours and boxes of the colour blobs the first image did not have that could be a
        cube and that the arm does not cover."""
        geom = FloorGeometry(np.asarray(self.T_SB, float), self.settings.floor_z_B_mm)
        model, R_SC = self.calib.model, self.calib.R_SC
        boxes: dict[int, tuple[str, tuple[int, int, int, int]]] = {}
        for c, m in masks.items():
            if c not in self.seen:
                continue
            new = cv2.morphologyEx(
                np.where(self.seen[c] > 0, 0, m).astype(np.uint8), cv2.MORPH_OPEN, _KERNEL3
            )
            n, _, stats, centroids = cv2.connectedComponentsWithStats(new, connectivity=4)
            for i in range(1, n):
                x, y, w, h, area = (int(v) for v in stats[i])
                if area < MIN_BLOB_PX:
                    continue
                verdict = blob_verdict(centroids[i], area, geom, model, R_SC, self.settings)
                if verdict is not None and not verdict[1]:
                    boxes[len(boxes)] = (c, (x, y, w, h))
        hidden = _boxes_hit({k: b for k, (_, b) in boxes.items()}, arm_px)
        return {k: b for k, b in boxes.items() if k not in hidden}

    def _is_new(
        self,
        cube: Cube,
        new_boxes: dict[int, tuple[str, tuple[int, int, int, int]]],
        arm_px: np.ndarray,
    ) -> bool:
        """A located cube is new when it lies on a new blob, the arm does not cover it and no
        known cube of its colour is within a cube's size of it."""
        x, y, w, h = (int(v) for v in cube.bbox)
        on_new = any(
            x < bx + bw and bx < x + w and y < by + bh and by < y + h
            for _, (bx, by, bw, bh) in new_boxes.values()
        )
        if not on_new or _boxes_hit({0: (x, y, w, h)}, arm_px):
            return False
        size = self.cfg.cube_size_mm
        return all(
            color != cube.color or float(np.linalg.norm(cube.center_B[:2] - c_B[:2])) >= size
            for color, _, _, c_B in self.ref.values()
        )


_Check = tuple[np.ndarray, list[np.ndarray], dict[str, np.ndarray]]


class ChangeWatch:
    """The sort's side of the checks: a check capture taken on a helper thread once a cube is
    lifted (`capture_now`), compared when the next pick is due (`settle`), and the
    queue and the report brought up to date with what it found."""

    def __init__(
        self,
        check: SceneCheck,
        camera: Any,
        arm: Any,
        relocate: Callable[[np.ndarray], list[Cube]],
        log: Any,
        new_outcome: Callable[[int, Cube], tuple[Any, bool]],
    ) -> None:
        self.check = check
        self.new_outcome = new_outcome
        self.camera = camera
        self.arm = arm
        self.relocate = relocate
        self.log = log
        self.results: list[dict[str, Any]] = []
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="scene-check")
        self._pending: Future[_Check] | None = None

    def _capture(self) -> _Check:
        """A check frame and every pose the arm went through while it was taken (read every
        JOINT_SAMPLE_S from before the grab to after it, and filled in by `swept_joints`):
        the arm moves during the grab, and a box it covered at the frame's instant cannot be
        judged."""
        qs = [np.asarray(self.arm.joint_positions(), float)]
        grabbed = threading.Event()

        def read_joints() -> None:
            while not grabbed.wait(JOINT_SAMPLE_S):
                qs.append(np.asarray(self.arm.joint_positions(), float))

        reader = threading.Thread(target=read_joints, name="check-joints", daemon=True)
        reader.start()
        try:
            image = self.camera.grab().image
        finally:
            grabbed.set()
            reader.join(CAPTURE_TIMEOUT_S)
        qs.append(np.asarray(self.arm.joint_positions(), float))
        return image, swept_joints(qs), colour_masks(self.check.cfg, image)

    def capture_now(self) -> None:
        """Start the check capture on the helper thread (it overlaps the arm's motion)."""
        self._pending = self._pool.submit(self._capture)

    def settle(self, queue: Any, nxt: tuple[int, Any] | None, outcomes: list[Any]) -> bool:
        """Compare the pending check capture for the cubes still to pick (and the next one,
        planned already); on a change the next plan is given back (the caller plans again
        with what is there now), moved cubes take their new pose and gone cubes leave the
        queue. True when something changed."""
        fut, self._pending = self._pending, None
        if fut is None:
            return False
        image, qs, masks = fut.result(timeout=CAPTURE_TIMEOUT_S)
        indices = list(queue.todo) + ([nxt[0]] if nxt is not None else [])
        res = self.check.check(image, indices, qs, self.relocate, masks)
        self.results.append(res.summary())
        if not res.changed:
            return False
        self.log.event("sorting/check", f"changed since the first capture: {res.summary()}")
        if nxt is not None:
            queue.give_back(*nxt)
        for k, cube in res.moved.items():
            queue.cubes[k] = cube
            queue._tried_with.pop(k, None)
            o = outcomes[k]
            o.center_S_mm, o.center_B_mm = cube.center_S.tolist(), cube.center_B.tolist()
            o.yaw_B_deg, o.sigma_mm = cube.yaw_B_deg, cube.sigma_mm
            o.relocated = True
        for k in res.gone:
            if k in queue.todo:
                queue.todo.remove(k)
            queue.gone.add(k)  # neither to pick nor an obstacle any more
            outcomes[k].status = "skipped"
            outcomes[k].reason = "gone: not where the first capture saw it (taken away?)"
        for cube in res.added:
            k = len(queue.cubes)
            queue.cubes.append(cube)
            self.check.add(k, cube, masks)
            out, to_pick = self.new_outcome(k, cube)
            outcomes.append(out)
            if to_pick:
                queue.todo.append(k)
        return True

    def close(self) -> None:
        self._pool.shutdown(wait=True)
