"""Pictures of what a measuring command detected and concluded: arrays in, BGR arrays out.

The one home of the product's review drawings and of their PNG encoding and atomic write:

- `draw_target_features`: the features extracted from a calibration image (markers, border,
  wall/floor line, laser stripe; board corners for the checkerboards);
- `draw_extrinsics`: those features with the fitted model reprojected through the fitted
  camera on top (each wall's border line and its laser line, or the laser line on each board)
  and a legend with the calibrated parameters: a border or stripe drawn beside its detected
  points is a calibration not to trust;
- `draw_map`: the laser points on the image and, beside it, the top view of the points on the
  laser plane (frame L, mm, with ticks), each segment in its own colour in both panels.

Drawing is vectorised (dots are stamped as index arrays); cv2 draws the lines and the text.
Colours are BGR (OpenCV), pixels (u, v) as in docs/frames.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration, place_side_walls
from omnisort_hw.core.features import BoardsFeatures, TargetFeatures, WallFeatures
from omnisort_hw.core.frames import great_circle_normal
from omnisort_hw.core.mapping import Segment, to_plane_frame
from omnisort_hw.core.records import PictureReply
from omnisort_hw.errors import StorageError
from omnisort_hw.fileio import atomic_write_bytes, os_error_text

Colour = tuple[int, int, int]

BORDER: Colour = (0, 255, 255)  # detected border (yellow)
FLOOR: Colour = (255, 255, 0)  # detected wall/floor line (cyan)
LASER: Colour = (0, 255, 0)  # detected laser stripe (green)
MARKER: Colour = (255, 80, 0)  # detected blue markers (rings)
CORNER: Colour = (255, 0, 255)  # detected board corners (magenta)
MODEL_BORDER: Colour = (255, 0, 255)  # fitted border line, reprojected (magenta)
MODEL_LASER: Colour = (0, 140, 255)  # fitted laser line, reprojected (orange)
_WHITE: Colour = (255, 255, 255)
_GREY: Colour = (150, 150, 150)
_FONT = cv2.FONT_HERSHEY_SIMPLEX
# Segment colours of the map (BGR), cycled; points in no segment are grey.
PALETTE: tuple[Colour, ...] = (
    (0, 200, 255),
    (255, 120, 0),
    (0, 230, 0),
    (255, 0, 200),
    (0, 80, 255),
    (255, 255, 0),
    (160, 0, 255),
    (0, 255, 180),
)
_SAMPLES = 80  # points per reprojected model line


# ---- primitives and files --------------------------------------------------------------------


def line_scale(image: np.ndarray) -> int:
    """Line thickness (px) that reads at the picture's size: 1 per 1000 px of width."""
    return max(1, round(image.shape[1] / 1000))


def draw_dots(
    image: np.ndarray, pts: np.ndarray, colour: Colour | np.ndarray, radius: int = 1
) -> np.ndarray:
    """Stamp filled discs of `radius` px at `pts` (N, 2) in place (one colour, or one per
    point as (N, 3)); points that are not finite or fall outside are skipped. Returns image."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    cols = np.broadcast_to(np.asarray(colour, np.uint8).reshape(-1, 3), (len(pts), 3))
    keep = np.all(np.isfinite(pts), axis=1)
    pts, cols = pts[keep], cols[keep]
    r = max(0, int(radius))
    oy, ox = np.mgrid[-r : r + 1, -r : r + 1]
    disc = ox**2 + oy**2 <= r * r + r
    centre = np.round(pts).astype(np.int64)
    u = (centre[:, 0:1] + ox[disc][None, :]).ravel()
    v = (centre[:, 1:2] + oy[disc][None, :]).ravel()
    c = np.repeat(cols, int(disc.sum()), axis=0)
    h, w = image.shape[:2]
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    image[v[inside], u[inside]] = c[inside]
    return image


def draw_polyline(
    image: np.ndarray, pts: np.ndarray, colour: Colour, thickness: int = 1
) -> np.ndarray:
    """Draw the polyline through `pts` (N, 2) in place, broken where a point is not finite."""
    pts = np.asarray(pts, float).reshape(-1, 2)
    ok = np.all(np.isfinite(pts), axis=1)
    runs = np.split(np.arange(len(pts)), np.flatnonzero(np.diff(ok.astype(int)) != 0) + 1)
    strips = [np.round(pts[r] * 16).astype(np.int32) for r in runs if len(r) > 1 and ok[r[0]]]
    if strips:
        cv2.polylines(image, strips, False, colour, thickness, cv2.LINE_AA, shift=4)
    return image


def put_text(
    image: np.ndarray, text: str, org: tuple[int, int], colour: Colour = _WHITE, scale=0.5
) -> None:
    """Text with a dark outline, readable on any background. The outline is the same text
    stamped one pixel around: OpenCV's font widens with the stroke, so a thicker outline ran
    past the text and read as a second copy, offset."""
    thick = max(1, round(scale * 2))
    x, y = org
    for dx, dy in ((-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)):
        cv2.putText(image, text, (x + dx, y + dy), _FONT, scale, (0, 0, 0), thick, cv2.LINE_AA)
    cv2.putText(image, text, org, _FONT, scale, colour, thick, cv2.LINE_AA)


def legend_panel(
    height: int,
    lines: Sequence[tuple[str, Colour | None]],
    keys: Sequence[tuple[str, Colour]] = (),
    scale: float = 0.45,
) -> np.ndarray:
    """A dark column `height` px tall, as wide as its text: lines of text (None: white), then a
    colour key (a swatch and its meaning). Beside a picture, it hides none of it."""
    step = round(22 * scale / 0.45)
    texts = [t for t, _ in lines] + [t for t, _ in keys]
    widest = max([cv2.getTextSize(t, _FONT, scale, 1)[0][0] for t in texts] + [0])
    panel = np.full((height, round(widest + 3.5 * step), 3), 20, np.uint8)
    y = step
    for text, colour in lines:
        put_text(panel, text, (step // 2, y), colour or _WHITE, scale)
        y += step
    y += step // 2
    for text, colour in keys:
        mid = y - step // 3
        cv2.line(panel, (step // 2, mid), (2 * step, mid), colour, max(2, step // 6))
        put_text(panel, text, (round(2.5 * step), y), _WHITE, scale)
        y += step
    return panel


def encode_png(image: np.ndarray) -> bytes:
    """PNG bytes of a BGR (or grey) picture."""
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(image))
    if not ok:
        raise ValueError("could not encode the picture as PNG")
    return buf.tobytes()


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """Write the picture as PNG atomically (readers never see half a file); StorageError names
    the path and the OS error when it cannot be written."""
    try:
        return atomic_write_bytes(path, encode_png(image), keep_history=False)
    except OSError as exc:
        raise StorageError(f"{path}: could not write the picture: {os_error_text(exc)}") from None


def write_picture(path: str | Path, draw: Callable[[], np.ndarray]) -> PictureReply:
    """Draw and write a command's picture, a by-product of its result: where it was written,
    or (no path) why not when drawing or writing failed, so a measurement already saved is
    still reported as done (a full disk or a read-only folder costs the picture only)."""
    try:
        return PictureReply(overlay_png=str(write_png(path, draw())))
    except StorageError as exc:
        why = str(exc)
    except Exception as exc:  # a drawing defect must not turn a saved calibration into an error
        why = f"{path}: the picture could not be drawn ({type(exc).__name__}: {exc})"
    return PictureReply(overlay_problem=why)


def overlay_path(out: str | Path) -> Path:
    """Where a command writing `out` puts its picture: beside it, `STEM_overlay.png`."""
    p = Path(out)
    return p.with_name(p.stem + "_overlay.png")


# ---- features --------------------------------------------------------------------------------


def draw_target_features(
    image: np.ndarray, features: TargetFeatures | BoardsFeatures
) -> np.ndarray:
    """A copy of the image with the features drawn: markers (blue rings, labelled), border
    (yellow), wall/floor line (cyan), laser (green), board corners (magenta, first one ringed)."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    thick = line_scale(out)
    if isinstance(features, BoardsFeatures):
        for name, board in features.boards.items():
            draw_dots(out, board.corners_px, CORNER, 2 * thick)
            c0 = np.round(board.corners_px[0]).astype(int)
            cv2.circle(out, (int(c0[0]), int(c0[1])), 6 * thick, CORNER, thick)
            draw_dots(out, board.laser_px, LASER, 2 * thick)
            cen = np.round(board.corners_px.mean(axis=0)).astype(int)
            put_text(out, name, (int(cen[0]), int(cen[1])), CORNER, 0.6 * thick)
        return out
    for wall_name, wall in features.walls.items():
        draw_dots(out, wall.border_px, BORDER, 2 * thick)
        draw_dots(out, wall.floor_px, FLOOR, 2 * thick)
        draw_dots(out, wall.laser_px, LASER, 2 * thick)
        for name, uv in wall.markers_px.items():
            p = np.round(np.asarray(uv, float)).astype(int)
            cv2.circle(out, (int(p[0]), int(p[1])), 8 * thick, MARKER, thick, cv2.LINE_AA)
            label = f"{wall_name[0].upper()}:{name}"
            put_text(out, label, (int(p[0]) + 10 * thick, int(p[1])), MARKER, 0.45 * thick)
    return out


# ---- the fitted model, reprojected ----------------------------------------------------------


@dataclass
class ModelLine:
    """One line of the fitted model in S, sampled, and its pixels through the fitted camera."""

    wall: str  # "left", "right", "far" (walls) or the board's name
    kind: str  # "border" or "laser"
    points_S: np.ndarray  # (N, 3) mm
    pixels: np.ndarray  # (N, 2), NaN where out of the camera's view


def project_S(calib: SystemCalibration, points_S: np.ndarray) -> np.ndarray:
    """Pixels of points in S through the fitted rotation and camera (NaN outside the view)."""
    rays = np.asarray(points_S, float).reshape(-1, 3) @ calib.R_SC  # rows: R^T p
    px = calib.model.ray_to_pixel(rays)
    return np.where(calib.model.in_view(rays)[:, None], px, np.nan)


def _laser_z(calib: SystemCalibration, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Z of the laser plane n . (p - (0, 0, -d)) = 0 over (x, y)."""
    n = calib.laser_normal
    return -calib.laser_distance_mm - (n[0] * x + n[1] * y) / n[2]


def wall_geometry(calib: SystemCalibration, features: TargetFeatures) -> dict[str, float]:
    """X of the side walls, Z of the border (and Y of a far wall) of the fitted model: the
    method's own figures where it records them, else placed from the detected borders with the
    fitted rotation and the known separation (`place_side_walls`), as `joint`'s start does."""
    t = calib.target
    sep = float(t.get("separation_mm") or 0.0)
    geom: dict[str, float] = {}
    if "wall_left_x_mm" in t and "border_z_mm" in t:
        geom["left"] = float(t["wall_left_x_mm"])
        geom["right"] = float(t.get("wall_right_x_mm", geom["left"] + sep))
        geom["z_b"] = float(t["border_z_mm"])
    elif sep > 0 and {"left", "right"} <= set(features.walls):
        m = [
            great_circle_normal(calib.model.pixel_to_ray(features.walls[s].border_px))
            for s in ("left", "right")
        ]
        geom["left"], geom["z_b"] = place_side_walls(calib.R_SC, m[0], m[1], sep)
        geom["right"] = geom["left"] + sep
    if "far_wall_y_mm" in t:
        geom["far"] = float(t["far_wall_y_mm"])
    return geom


def _extent(
    calib: SystemCalibration, wall: WallFeatures, axis: int, at: float
) -> tuple[float, float]:
    """Range along the wall of its detected features: their rays cut with the wall's plane
    (coordinate `axis` of S equal to `at`), widened by 4 % at each end."""
    px = [wall.border_px, wall.laser_px, wall.floor_px, *wall.markers_px.values()]
    pts = np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in px])
    rays = calib.model.pixel_to_ray(pts) @ calib.R_SC.T
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = at / rays[:, axis]
    along = (rays * scale[:, None])[scale > 0][:, 1 - axis]
    lo, hi = float(along.min()), float(along.max())
    pad = 0.04 * (hi - lo)
    return lo - pad, hi + pad


def model_lines(
    calib: SystemCalibration, features: TargetFeatures | BoardsFeatures
) -> list[ModelLine]:
    """The fitted model's lines where the features were seen: each wall's border line and laser
    line (wall plane cut with the laser plane), or the laser line on each board's plane."""
    if isinstance(features, BoardsFeatures):
        return _board_lines(calib, features)
    geom = wall_geometry(calib, features)
    out: list[ModelLine] = []
    for name, wall in features.walls.items():
        if name not in geom or "z_b" not in geom:
            continue
        axis = 1 if name == "far" else 0  # a side wall is X = const, the far wall Y = const
        lo, hi = _extent(calib, wall, axis, geom[name])
        along = np.linspace(lo, hi, _SAMPLES)
        fixed = np.full(_SAMPLES, geom[name])
        x, y = (along, fixed) if axis == 1 else (fixed, along)
        for kind, z in (
            ("border", np.full(_SAMPLES, geom["z_b"])),
            ("laser", _laser_z(calib, x, y)),
        ):
            pts = np.stack([x, y, z], axis=1)
            out.append(ModelLine(name, kind, pts, project_S(calib, pts)))
    return out


def _board_lines(calib: SystemCalibration, features: BoardsFeatures) -> list[ModelLine]:
    """Laser line on each board: the board's plane (its pose, `target.boards`) cut with the
    fitted laser plane, across the board's corner extent widened by one square."""
    poses = calib.target.get("boards", {})
    n_S, d = calib.laser_normal, calib.laser_distance_mm
    out = []
    for name, board in features.boards.items():
        if name not in poses:
            continue
        T = np.asarray(poses[name]["pose_C"], float)
        R_SB = calib.R_SC @ T[:3, :3]  # board axes in S
        t_S = calib.R_SC @ T[:3, 3]
        cols, rows = board.inner_corners
        s = board.square_mm
        # On the board (x, y, 0): n . (R_SB (x, y, 0) + t - (0, 0, -d)) = 0, a x + b y = c.
        a, b = n_S @ R_SB[:, 0], n_S @ R_SB[:, 1]
        c = -(n_S @ (t_S + np.array([0.0, 0.0, d])))
        if abs(b) >= abs(a):
            x = np.linspace(-s, cols * s, _SAMPLES)
            y = (c - a * x) / b
        else:
            y = np.linspace(-s, rows * s, _SAMPLES)
            x = (c - b * y) / a
        inside = (x >= -s) & (x <= cols * s) & (y >= -s) & (y <= rows * s)
        if inside.sum() < 2:
            continue
        local = np.stack([x[inside], y[inside], np.zeros(int(inside.sum()))], axis=1)
        pts = local @ R_SB.T + t_S
        out.append(ModelLine(name, "laser", pts, project_S(calib, pts)))
    return out


def _fmt_param(key: str, value: float, std: float | None) -> str:
    unit = "mm" if key.endswith("_mm") else "deg"
    name = key.removesuffix("_mm").removesuffix("_deg").replace("_", " ")
    spread = f" +- {std:.3f}" if std is not None else ""
    return f"{name:<15} {value:9.3f}{spread} {unit}"


def draw_extrinsics(
    image: np.ndarray,
    features: TargetFeatures | BoardsFeatures,
    calib: SystemCalibration,
    title: str = "",
) -> np.ndarray:
    """The calibration image with the detected features (dots) and the fitted model's lines
    reprojected through the fitted camera (thin lines over them), and to its right a legend
    column of the method, parameters and fit: the picture is the image's height, and its
    width plus the legend's (the image keeps its pixel coordinates, from the top left)."""
    out = draw_target_features(image, features)
    thick = line_scale(out)
    for line in model_lines(calib, features):
        colour = MODEL_BORDER if line.kind == "border" else MODEL_LASER
        draw_polyline(out, line.pixels, colour, thick)
    kind = features.kind if isinstance(features, TargetFeatures) else "checkerboards"
    lines: list[tuple[str, Colour | None]] = [
        (f"extrinsics: {calib.method} on the {kind} target", None),
    ]
    if title:
        lines.append((title, _GREY))
    for key, value in calib.parameters().items():
        lines.append((_fmt_param(key, value, calib.std.get(key)), None))
    if "rms_px" in calib.residuals:
        lines.append((f"fit residual RMS {calib.residuals['rms_px']:.3f} px", None))
    if calib.target.get("separation_mm"):
        lines.append((f"wall separation {calib.target['separation_mm']:.1f} mm (given)", _GREY))
    keys = [
        ("detected border", BORDER),
        ("detected wall/floor line", FLOOR),
        ("detected laser stripe", LASER),
        ("detected markers", MARKER),
        ("fitted border, reprojected", MODEL_BORDER),
        ("fitted laser line, reprojected", MODEL_LASER),
    ]
    if kind == "checkerboards":
        keys = [keys[2], ("detected board corners", CORNER), keys[5]]
    panel = legend_panel(out.shape[0], lines, keys, 0.45 * thick)
    return np.concatenate([out, panel], axis=1)


# ---- the laser map ---------------------------------------------------------------------------


def segment_labels(points_S: np.ndarray, segs: Sequence[Segment]) -> np.ndarray:
    """Index of the segment holding each point (-1: none), by exact equality of the points."""
    pts = np.asarray(points_S, float).reshape(-1, 3)
    labels = np.full(len(pts), -1)
    if not segs or not len(pts):
        return labels
    seg_pts = np.concatenate([s.points_S for s in segs])
    seg_ids = np.concatenate([np.full(len(s.points_S), i) for i, s in enumerate(segs)])
    every = np.concatenate([pts, seg_pts])
    _, inverse = np.unique(every, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    lut = np.full(inverse.max() + 1, -1)
    lut[inverse[len(pts) :]] = seg_ids
    labels = lut[inverse[: len(pts)]]
    return np.where(np.all(np.isfinite(pts), axis=1), labels, -1)


def _colours(labels: np.ndarray) -> np.ndarray:
    table = np.array([*PALETTE, _GREY], np.uint8)
    return table[np.where(labels >= 0, labels % len(PALETTE), len(PALETTE))]


def nice_step(span: float, ticks: int = 6) -> float:
    """A 1, 2 or 5 times a power of ten step giving about `ticks` intervals over `span`."""
    raw = max(span, 1e-9) / ticks
    power = 10.0 ** math.floor(math.log10(raw))
    return next(m * power for m in (1, 2, 5, 10) if m * power >= raw)


def draw_top_view(
    size: int,
    points_L: np.ndarray,
    labels: np.ndarray,
    segs: Sequence[Segment],
    calib: SystemCalibration,
    point_colours: np.ndarray | None = None,
) -> np.ndarray:
    """Square panel: the points on the laser plane (L: x_l right, y_l up, as the image shows
    X and Y), grid and ticks in mm, the camera axis' foot at the origin, and each segment's
    number and distance at its point nearest the axis (ringed)."""
    panel = np.full((size, size, 3), 25, np.uint8)
    pts = np.asarray(points_L, float).reshape(-1, 2)
    ok = np.all(np.isfinite(pts), axis=1)
    data = np.concatenate([pts[ok], np.zeros((1, 2))])
    lo, hi = data.min(axis=0), data.max(axis=0)
    span = float(max(hi - lo)) * 1.12 or 100.0
    mid = (lo + hi) / 2
    margin = round(0.09 * size)
    scale = (size - 2 * margin) / span

    def to_px(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, float).reshape(-1, 2)
        return np.stack(
            [size / 2 + (p[:, 0] - mid[0]) * scale, size / 2 - (p[:, 1] - mid[1]) * scale], axis=1
        )

    text = 0.4 * max(1.0, size / 1000)
    step = nice_step(span)
    lo_w, hi_w = mid - span / 2, mid + span / 2
    for axis in (0, 1):
        for val in np.arange(math.ceil(lo_w[axis] / step) * step, hi_w[axis], step):
            a = np.array([val, lo_w[1]]) if axis == 0 else np.array([lo_w[0], val])
            b = np.array([val, hi_w[1]]) if axis == 0 else np.array([hi_w[0], val])
            colour = (110, 110, 110) if abs(val) < step / 2 else (55, 55, 55)
            draw_polyline(panel, to_px(np.stack([a, b])), colour, 1)
            pa = to_px(a)[0]
            org = (round(pa[0]) - 18, size - margin // 3) if axis == 0 else (4, round(pa[1]) + 4)
            put_text(panel, f"{val:.0f}", org, _GREY, text)
    radius = max(1, size // 700)
    cols = _colours(labels[ok]) if point_colours is None else np.asarray(point_colours)[ok]
    draw_dots(panel, to_px(pts[ok]), cols, radius)
    origin = np.round(to_px(np.zeros(2))[0]).astype(int)
    cv2.drawMarker(panel, (int(origin[0]), int(origin[1])), _WHITE, cv2.MARKER_CROSS, 14, 1)
    put_text(panel, "camera axis", (int(origin[0]) + 8, int(origin[1]) - 8), _WHITE, text)
    for i, seg in enumerate(segs):
        seg_L = to_plane_frame(seg.points_S, calib)
        nearest = seg_L[np.argmin(np.hypot(seg.points_S[:, 0], seg.points_S[:, 1]))]
        at = np.round(to_px(nearest)[0]).astype(int)
        colour = PALETTE[i % len(PALETTE)]
        cv2.circle(panel, (int(at[0]), int(at[1])), 3 * radius + 3, colour, 1, cv2.LINE_AA)
        label = f"{i}: {seg.distance_mm:.0f} mm"
        below = 8 + round(30 * text) if i % 2 else -8  # neighbours' labels do not collide
        put_text(panel, label, (int(at[0]) + 8, int(at[1]) + below), colour, text)
    put_text(
        panel,
        f"top view on the laser plane (L): x_l right, y_l up; grid {step:g} mm",
        (8, round(margin * 0.45)),
        _WHITE,
        text * 1.1,
    )
    return panel


def draw_map(
    image: np.ndarray,
    pixels: np.ndarray,
    points_S: np.ndarray,
    segs: Sequence[Segment],
    calib: SystemCalibration,
    title: str = "",
    sigma_mm: np.ndarray | None = None,
) -> np.ndarray:
    """The map's picture, the image's height: the image (its pixel coordinates kept) with the
    laser points, a square top view of the points on the laser plane, and a legend column;
    points in a segment share its colour in both, grey ones are in none. With `sigma_mm`
    (each point's sigma along the surface normal) a second top view colours the points by it
    (blue 0 to red at its 95th percentile)."""
    left = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    labels = segment_labels(points_S, segs)
    thick = line_scale(left)
    draw_dots(left, pixels, _colours(labels), thick)
    lines: list[tuple[str, Colour | None]] = [
        (f"map: {len(pixels)} laser points, {len(segs)} segments", None)
    ]
    if title:
        lines.append((title, _GREY))
    p = calib.parameters()
    lines.append(
        (
            f"laser plane: roll {p['laser_roll_deg']:.2f} pitch {p['laser_pitch_deg']:.2f} deg,"
            f" d {p['laser_distance_mm']:.1f} mm ({calib.method})",
            _GREY,
        )
    )
    for i, seg in enumerate(segs[: len(PALETTE) * 2]):
        lines.append(
            (
                f"{i}: {len(seg.points_S)} pts, {seg.distance_mm:.0f} mm at "
                f"{seg.bearing_deg:.0f} deg, {seg.length_mm:.0f} mm long",
                PALETTE[i % len(PALETTE)],
            )
        )
    finite = np.all(np.isfinite(np.asarray(points_S, float).reshape(-1, 3)), axis=1)
    points_L = np.full((len(finite), 2), np.nan)
    if finite.any():
        points_L[finite] = to_plane_frame(np.asarray(points_S, float)[finite], calib)
    top = draw_top_view(left.shape[0], points_L, labels, segs, calib)
    panels = [left, top]
    if sigma_mm is not None and np.isfinite(sigma_mm).any():
        sig = np.asarray(sigma_mm, float)
        hi = float(np.nanpercentile(sig, 95)) or 1.0
        level = np.clip(np.nan_to_num(sig / hi) * 255, 0, 255).astype(np.uint8)
        cols = cv2.applyColorMap(level.reshape(-1, 1), cv2.COLORMAP_JET).reshape(-1, 3)
        panels.append(draw_top_view(left.shape[0], points_L, labels, [], calib, cols))
        lines.append((f"sigma along the surface normal: blue 0 .. red {hi:.2f} mm", None))
        lines.append((f"median {float(np.nanmedian(sig)):.2f} mm", _GREY))
    legend = legend_panel(left.shape[0], lines, (), 0.45 * thick)
    return np.concatenate([*panels, legend], axis=1)
