"""Features of the calibration targets and the checkerboard baseline, from one fisheye image.

What is extracted (records in `features.py`, the contract with the calibration methods):

- Blue markers, found and named by wall from their geometry: `target_markers.py`.
- Two-sided target: a white far wall with a black/white border between the far markers means
  the image shows the three-sided target, which is an error rather than two walls silently
  extracted from it.
- Border (and wall/floor line) of each wall, along the great circle through its two markers:
  `target_edges.py`. `floor_px` is the wall/floor line; it is optional (empty when not found),
  the rest is not.
- Laser: `laser_stripe_points` once for the image, then the points whose rays fall inside the
  wall's white face (the spherical quadrilateral bounded by the border, the floor line or the
  floor markers, and the great circles through each end's two markers), and of those the
  inliers of one great circle (the stripe on a flat wall is a straight 3D line); a stepped
  (aliased) stripe is put back on the line through its risers' midpoints (`stripe_steps`).

Three-sided target: walls "left", "right" and "far". Two marker layouts are understood:
the published one (8 markers; the side walls' far markers stand at the corners with the far
wall, which has none of its own: its markers dict is empty and its face is bounded by those
corner markers) and the simulator's (12 markers, four on each wall; the far wall's are named
as the simulator names them: "near" is its left end (-X), "far" its right end).

Checkerboards: one full board is detected (on the whole image, else on each half of it), masked
out, and the second one detected the same way; the one further towards -X (larger azimuth in S)
is "left", the other "far". The laser points on each board are those inside the board's outline
(inner corners extended by most of a square), filtered to one great circle.

Every failure raises `FeatureNotFoundError` saying what was not found and where, and an image
whose size differs from the camera model's raises `InputError`; nothing is returned half-found.
"""

from __future__ import annotations

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.checkerboard import detect_corners
from omnisort_hw.core.features import (
    MARKER_NAMES,
    BoardFeatures,
    BoardsFeatures,
    TargetFeatures,
    WallFeatures,
)
from omnisort_hw.core.great_circles import _fmt, _nominal_S, _unit, fit_great_circle, pixel_scale
from omnisort_hw.core.laser_stripe import check_bgr, laser_stripe_points
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.core.stripe_steps import unstep_stripe
from omnisort_hw.core.target_edges import LineEdge, find_line_edge
from omnisort_hw.core.target_markers import SIDES, Blob, assign_markers, find_blue_markers
from omnisort_hw.errors import FeatureNotFoundError, InputError

KINDS = ("two-sided", "three-sided")

_LASER_TOL_PX = 1.5  # great-circle inlier tolerance of laser points
_LASER_MIN_POINTS = 8
_FACE_MARGIN_PX = 3.0  # laser points this close to a face's boundary are left out


def _gray(image: np.ndarray) -> np.ndarray:
    """Encoded grey levels (for face brightness checks, not for locating edges)."""
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(np.float32)


# ---- wall faces and laser --------------------------------------------------------------------


def _face_planes(
    model: OcamModel,
    border_a: Blob,
    border_b: Blob,
    floor_a: Blob,
    floor_b: Blob,
    border_normal: np.ndarray,
    floor_normal: np.ndarray | None,
) -> np.ndarray:
    """Inward unit normals (4, 3) of the great circles bounding a wall's white face: border,
    floor line (or the floor markers' circle), and the two ends (each end's two markers)."""
    ba, bb, fa, fb = model.pixel_to_ray(
        np.stack([b.uv for b in (border_a, border_b, floor_a, floor_b)])
    )
    centre = _unit(ba + bb + fa + fb)
    floor_n = floor_normal if floor_normal is not None else _unit(np.cross(fa, fb))
    planes = np.stack([border_normal, floor_n, _unit(np.cross(ba, fa)), _unit(np.cross(bb, fb))])
    return planes * np.where(planes @ centre < 0, -1.0, 1.0)[:, None]


def _laser_on_face(
    model: OcamModel,
    stripe: np.ndarray,
    stripe_rays: np.ndarray,
    planes: np.ndarray,
    what: str,
    corners: list[Blob],
) -> np.ndarray:
    """Stripe points inside the face, then the inliers of one great circle."""
    scale = pixel_scale(model, stripe_rays) if stripe.shape[0] else np.zeros(0)
    inside = np.all(
        stripe_rays @ planes.T > (_FACE_MARGIN_PX / np.maximum(scale, 1e-9))[:, None], axis=1
    )
    pts = stripe[inside]
    where = "the white face between the markers at " + ", ".join(_fmt(c.uv) for c in corners)
    if pts.shape[0] < _LASER_MIN_POINTS:
        raise FeatureNotFoundError(
            f"{what}: no laser stripe on {where} ({pts.shape[0]} stripe points there, at least "
            f"{_LASER_MIN_POINTS} needed); is the laser on and crossing the wall?"
        )
    normal, inl, _ = fit_great_circle(model, pts, _LASER_TOL_PX)
    if inl.sum() < _LASER_MIN_POINTS:
        raise FeatureNotFoundError(
            f"{what}: the {pts.shape[0]} stripe points on {where} do not form one straight laser "
            f"line ({int(inl.sum())} on one great circle)"
        )
    return unstep_stripe(model, pts[inl], normal)


def check_image(image_bgr: np.ndarray, model: OcamModel) -> np.ndarray:
    """The image as uint8 BGR, or InputError when it is not one or its size is not the model's."""
    img = check_bgr(image_bgr)
    size = (img.shape[1], img.shape[0])
    if size != tuple(model.image_size):
        raise InputError(
            f"image is {size[0]}x{size[1]} but the camera model is for "
            f"{model.image_size[0]}x{model.image_size[1]}: wrong camera, mode or model file"
        )
    return img


def _stripe(
    image: np.ndarray, model: OcamModel, given: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    stripe = laser_stripe_points(image) if given is None else np.asarray(given, float)
    if stripe.shape[0] == 0:
        raise FeatureNotFoundError(
            "no laser stripe anywhere in the image: is the laser on (and not too faint)?"
        )
    return stripe, model.pixel_to_ray(stripe)


def _wall(
    gray: np.ndarray,
    model: OcamModel,
    name: str,
    m: dict[str, Blob],
    ends: tuple[str, str],
    stripe: tuple[np.ndarray, np.ndarray],
    exclude: list[Blob],
) -> WallFeatures:
    """Border, floor line and laser of one wall whose markers are named m[border_/floor_ + end]."""
    e0, e1 = ends
    bn, bf, fn, ff = m[f"border_{e0}"], m[f"border_{e1}"], m[f"floor_{e0}"], m[f"floor_{e1}"]
    r_floor = model.pixel_to_ray(np.stack([fn.uv, ff.uv])).mean(axis=0)
    r_border = model.pixel_to_ray(np.stack([bn.uv, bf.uv])).mean(axis=0)
    border = find_line_edge(gray, model, bn, bf, r_floor, f"{name} wall border", exclude)
    try:
        floor: LineEdge | None = find_line_edge(
            gray, model, fn, ff, r_border, f"{name} wall/floor line", exclude, below_only=True
        )
    except FeatureNotFoundError:
        floor = None
    planes = _face_planes(
        model, bn, bf, fn, ff, border.normal, None if floor is None else floor.normal
    )
    laser = _laser_on_face(model, *stripe, planes, f"{name} wall", [bn, bf, ff, fn])
    markers = {k: v.uv.copy() for k, v in m.items() if k in MARKER_NAMES}
    return WallFeatures(
        border_px=border.points,
        laser_px=laser,
        markers_px=markers,
        floor_px=floor.points if floor is not None else np.zeros((0, 2)),
    )


def _face_level(
    gray: np.ndarray, model: OcamModel, m: dict[str, Blob], ends: tuple[str, str]
) -> float:
    """Median grey level inside the quadrilateral of a wall's four markers (its white face)."""
    e0, e1 = ends
    c = model.pixel_to_ray(
        np.stack(
            [m[f"floor_{e0}"].uv, m[f"floor_{e1}"].uv, m[f"border_{e0}"].uv, m[f"border_{e1}"].uv]
        )
    )
    s, t = np.meshgrid(np.linspace(0.25, 0.75, 7), np.linspace(0.2, 0.6, 5))
    s, t = s.ravel()[:, None], t.ravel()[:, None]
    rays = (1 - s) * (1 - t) * c[0] + s * (1 - t) * c[1] + (1 - s) * t * c[2] + s * t * c[3]
    uv = model.ray_to_pixel(_unit(rays)).astype(np.float32)
    vals = cv2.remap(
        gray, uv[:, 0:1], uv[:, 1:2], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    )
    return float(np.median(vals))


def _check_far_end_open(
    gray: np.ndarray,
    model: OcamModel,
    walls_m: dict[str, dict[str, Blob]],
    corners: dict[str, Blob],
    used: list[Blob],
) -> None:
    """Two-sided target: no third wall may close the far end (a face as white as the side walls'
    below a black/white border from one far border marker to the other), else the image shows
    the three-sided target and a two-sided calibration would silently ignore its far wall."""
    white = min(_face_level(gray, model, walls_m[s], ("near", "far")) for s in SIDES)
    if _face_level(gray, model, corners, ("near", "far")) < 0.8 * white:
        return
    r_floor = model.pixel_to_ray(np.stack([corners["floor_near"].uv, corners["floor_far"].uv]))
    try:
        find_line_edge(
            gray,
            model,
            corners["border_near"],
            corners["border_far"],
            r_floor.mean(axis=0),
            "far wall border",
            used,
        )
    except FeatureNotFoundError:
        return
    raise FeatureNotFoundError(
        "two-sided target: a third white wall with a black/white border closes the far end "
        f"between the markers at {_fmt(corners['border_near'].uv)} and "
        f"{_fmt(corners['border_far'].uv)}; this looks like the three-sided target"
    )


def extract_target_features(
    image_bgr: np.ndarray,
    model: OcamModel,
    kind: str = "two-sided",
    tone: ToneCurve = SRGB,
    stripe_px: np.ndarray | None = None,
) -> TargetFeatures:
    """Markers, borders, wall/floor lines and laser points of every wall of the target.
    `tone`: the camera's tone curve; edges and marker coverage are measured in linear light.
    `stripe_px`: the stripe's points when measured apart (a laser on/off capture); by
    default they are found in the image."""
    if kind not in KINDS:
        raise InputError(f"target kind must be one of {', '.join(KINDS)}, got {kind!r}")
    image = check_image(image_bgr, model)
    walls_m, used = assign_markers(find_blue_markers(image, tone), model, kind)
    gray = _gray(image)
    light = tone.luminance(image)
    stripe = _stripe(image, model, stripe_px)
    walls: dict[str, WallFeatures] = {}
    for side in SIDES:
        walls[side] = _wall(light, model, side, walls_m[side], ("near", "far"), stripe, used)
    left, right = walls_m["left"], walls_m["right"]
    own = walls_m.get("far", {})
    corners = own or {
        "border_near": left["border_far"],
        "floor_near": left["floor_far"],
        "border_far": right["border_far"],
        "floor_far": right["floor_far"],
    }
    if kind == "two-sided":
        _check_far_end_open(gray, model, walls_m, corners, used)
    else:
        try:
            far = _wall(light, model, "far", corners, ("near", "far"), stripe, used)
        except FeatureNotFoundError as exc:
            raise FeatureNotFoundError(f"{exc} (is this the two-sided target?)") from None
        if not own:
            far.markers_px = {}
        walls["far"] = far
    return TargetFeatures(kind, (image.shape[1], image.shape[0]), walls)


# ---- checkerboards ---------------------------------------------------------------------------


def _board_outline(corners: np.ndarray, cols: int, rows: int, extend: float) -> np.ndarray:
    """Polygon (P, 2) around the board: its boundary corners pushed out by `extend` squares
    (each along the local grid direction, so it follows the fisheye's curvature)."""
    g = corners.reshape(rows, cols, 2)
    out = g.copy()
    out[0] += extend * (g[0] - g[1])
    out[-1] += extend * (g[-1] - g[-2])
    out[:, 0] += extend * (g[:, 0] - g[:, 1])
    out[:, -1] += extend * (g[:, -1] - g[:, -2])
    ring = np.concatenate([out[0, :], out[1:, -1], out[-1, -2::-1], out[-2:0:-1, 0]])
    return ring


def _board_mask(shape: tuple[int, int], outline: np.ndarray) -> np.ndarray:
    mask = np.zeros(shape, np.uint8)
    cv2.fillPoly(mask, [np.round(outline).astype(np.int32)], 1)
    return mask.astype(bool)


def _detect_board(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """One full board: on the whole image, else on each half with the rest greyed out (two
    boards side by side can confuse the detector's quad linking; alone, each is found)."""
    try:
        return detect_corners(image, size)
    except FeatureNotFoundError as exc:
        first_error = exc
    h, w = image.shape[:2]
    halves = (
        (slice(0, h // 2 + h // 8), slice(None)),
        (slice(None), slice(0, w // 2 + w // 8)),
        (slice(None), slice(w // 2 - w // 8, w)),
        (slice(h // 2 - h // 8, h), slice(None)),
    )
    for rows, cols in halves:
        part = np.full_like(image, 128)
        part[rows, cols] = image[rows, cols]
        try:
            return detect_corners(part, size)
        except FeatureNotFoundError:
            continue
    raise first_error


def extract_board_features(
    image_bgr: np.ndarray,
    model: OcamModel,
    inner_corners: tuple[int, int] = (9, 6),
    square_mm: float = 97.0,
    stripe_px: np.ndarray | None = None,
) -> BoardsFeatures:
    """Corners of the two perpendicular boards ("left", "far") and the laser on each
    (`stripe_px`: the stripe measured apart, else found in the image)."""
    image = check_image(image_bgr, model)
    cols, rows = inner_corners
    h, w = image.shape[:2]
    try:
        first = _detect_board(image, (cols, rows))
    except FeatureNotFoundError as exc:
        raise FeatureNotFoundError(f"checkerboard target: {exc}") from None
    masked = image.copy()
    masked[_board_mask((h, w), _board_outline(first, cols, rows, 1.5))] = 128
    try:
        second = _detect_board(masked, (cols, rows))
    except FeatureNotFoundError:
        raise FeatureNotFoundError(
            f"checkerboard target: one {cols}x{rows} board found around "
            f"{_fmt(first.mean(axis=0))}, the second (perpendicular) board was not found"
        ) from None
    boards = [first, second]
    S = _nominal_S(model.pixel_to_ray(np.stack([b.mean(axis=0) for b in boards])))
    azimuth = np.arctan2(S[:, 1], S[:, 0])
    left_i = int(np.argmax(azimuth))
    stripe = laser_stripe_points(image) if stripe_px is None else np.asarray(stripe_px, float)
    if stripe.shape[0] == 0:
        raise FeatureNotFoundError(
            "no laser stripe anywhere in the image: is the laser on (and not too faint)?"
        )
    out: dict[str, BoardFeatures] = {}
    for i, corners in enumerate(boards):
        name = "left" if i == left_i else "far"
        mask = _board_mask((h, w), _board_outline(corners, cols, rows, 0.8))
        ij = np.clip(np.round(stripe).astype(int), 0, [w - 1, h - 1])
        pts = stripe[mask[ij[:, 1], ij[:, 0]]]
        where = f"the {name} board around {_fmt(corners.mean(axis=0))}"
        if pts.shape[0] < _LASER_MIN_POINTS:
            raise FeatureNotFoundError(
                f"{name} board: no laser stripe on {where} ({pts.shape[0]} stripe points, at "
                f"least {_LASER_MIN_POINTS} needed); is the laser on and crossing the board?"
            )
        _, inl, _ = fit_great_circle(model, pts, _LASER_TOL_PX)
        if inl.sum() < _LASER_MIN_POINTS:
            raise FeatureNotFoundError(
                f"{name} board: the stripe points on {where} do not form one straight line"
            )
        out[name] = BoardFeatures(name, (cols, rows), float(square_mm), corners, pts[inl])
    return BoardsFeatures((w, h), {"left": out["left"], "far": out["far"]})
