"""The intrinsic calibration's report: what a technician looks at before trusting a lens model.

Figures (pure numbers, `report_figures`) and one picture (`render_report`, a BGR array):
- the image circle with every used corner and its residual vector, scaled up;
- the residual against the distance from the distortion centre, with its binned RMS (a
  rising trend at the rim means the model or the corners fail there);
- the coverage of the circle's outer 20 % of radius by corners, with a warning when low (the
  extrinsic targets and the laser line live there, and the polynomial is only known where
  corners were);
- per-image RMS, and every dropped image and corner with its reason.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import cv2
import numpy as np

from omnisort_hw.core.intrinsics import IntrinsicResult

OUTER_BAND = 0.2  # the outer fraction of the image circle's radius whose coverage is measured
SECTORS = 36  # angular sectors of that band
LOW_COVERAGE = 0.5  # below this covered fraction the report warns

_W, _H = 1600, 1000
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_WHITE, _GREY, _RED, _AMBER = (255, 255, 255), (150, 150, 150), (60, 60, 230), (0, 170, 255)


@dataclass
class ReportFigures:
    """The report's numbers (also logged and printed)."""

    circle_radius_px: float
    outer_coverage: float  # fraction of the outer band's sectors (inside the image) with corners
    sectors_inside: int
    residual_by_radius: list[tuple[float, float, int]]  # (radius px, RMS px, corners) per bin
    warning: str | None
    circle_field_deg: float = 0.0  # across the lit image circle, through the fitted model
    corners_field_deg: float = 0.0  # twice the largest angle from the axis of a used corner


def image_circle_radius(grays: list[np.ndarray], centre: tuple[float, float]) -> float:
    """Radius of the lit image circle about `centre`: the largest radius at which at least
    half of the pixels (of those inside the frame) are lit in the mean image, lit meaning
    above a quarter of the way from its dark floor to its bright level."""
    mean = np.mean([g.astype(np.float32) for g in grays], axis=0)
    lo, hi = np.percentile(mean, [1.0, 90.0])
    lit = mean > lo + 0.25 * (hi - lo)
    v, u = np.indices(mean.shape)
    radius = np.hypot(u - centre[0], v - centre[1]).astype(int)
    counts = np.bincount(radius.ravel())
    lit_counts = np.bincount(radius.ravel(), weights=lit.ravel().astype(float))
    frac = lit_counts / np.maximum(counts, 1)
    good = np.flatnonzero((frac >= 0.5) & (counts > 0))
    return float(good.max()) if good.size else 0.5 * float(min(mean.shape))


def band_coverage(
    points: np.ndarray, centre: tuple[float, float], radius: float, image_size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """(covered, inside), each (SECTORS,) bool: the sectors of the circle's outer band (the
    outer OUTER_BAND of `radius` about `centre`) holding one of `points` ((N, 2) px), and those
    whose middle lies inside the (width, height) frame. Sector k spans the angles
    [-pi + k 2pi/SECTORS, -pi + (k + 1) 2pi/SECTORS) of atan2(v - cv, u - cu)."""
    cu, cv_ = centre
    pts = np.asarray(points, float).reshape(-1, 2)
    rho = np.hypot(pts[:, 0] - cu, pts[:, 1] - cv_)
    ang = np.arctan2(pts[:, 1] - cv_, pts[:, 0] - cu)
    w, h = image_size
    edges = np.linspace(-np.pi, np.pi, SECTORS + 1)
    mid_a = 0.5 * (edges[:-1] + edges[1:])
    mid_r = (1.0 - 0.5 * OUTER_BAND) * radius
    mu, mv = cu + mid_r * np.cos(mid_a), cv_ + mid_r * np.sin(mid_a)
    inside = (mu >= 0) & (mu < w) & (mv >= 0) & (mv < h)
    in_band = rho >= (1.0 - OUTER_BAND) * radius
    sector = np.clip(np.digitize(ang[in_band], edges) - 1, 0, SECTORS - 1)
    covered = np.zeros(SECTORS, bool)
    covered[sector] = True
    return covered, inside


def covered_fraction(covered: np.ndarray, inside: np.ndarray) -> float:
    """The share of the band's sectors inside the frame that hold a point."""
    return float(np.sum(covered & inside) / max(int(inside.sum()), 1))


def report_figures(
    result: IntrinsicResult, image_size: tuple[int, int], radius: float
) -> ReportFigures:
    """Coverage of the outer band and residual against radius."""
    cu, cv_ = result.model.center_uv
    pts = np.concatenate([result.corners_px[n] for n in result.images_used])
    res = np.concatenate([result.residuals_px[n] for n in result.images_used])
    rho = np.hypot(pts[:, 0] - cu, pts[:, 1] - cv_)
    covered, inside = band_coverage(pts, (cu, cv_), radius, image_size)
    coverage = covered_fraction(covered, inside)
    bins = np.linspace(0.0, radius, 11)
    dist = np.linalg.norm(res, axis=1)
    by_radius = []
    for lo, hi in itertools.pairwise(bins):
        sel = (rho >= lo) & (rho < hi)
        if sel.any():
            rms = float(np.sqrt(np.mean(dist[sel] ** 2)))
            by_radius.append((float(0.5 * (lo + hi)), rms, int(sel.sum())))
    warning = None
    if coverage < LOW_COVERAGE:
        warning = (
            f"only {coverage:.0%} of the outer {OUTER_BAND:.0%} of the image circle has corners: "
            "add views with the board near the rim, where the targets and the laser line are"
        )
    model = result.model
    across = np.array([[cu - radius, cv_], [cu + radius, cv_]])
    circle_field = float(np.degrees(np.sum(model.angle_from_axis(model.pixel_to_ray(across)))))
    corners_field = float(np.degrees(2 * np.max(model.angle_from_axis(model.pixel_to_ray(pts)))))
    return ReportFigures(
        radius, coverage, int(inside.sum()), by_radius, warning, circle_field, corners_field
    )


def render_report(
    result: IntrinsicResult,
    background: np.ndarray,
    figures: ReportFigures,
) -> np.ndarray:
    """The report as one BGR picture (_W x _H)."""
    canvas = np.full((_H, _W, 3), 30, np.uint8)
    _circle_panel(canvas, result, background, figures)
    _radius_panel(canvas, result, figures)
    _text_panel(canvas, result, figures)
    return canvas


def _put(img: np.ndarray, text: str, org: tuple[int, int], color=_WHITE, scale=0.5) -> None:
    cv2.putText(img, text, org, _FONT, scale, color, 1, cv2.LINE_AA)


def _circle_panel(
    canvas: np.ndarray, result: IntrinsicResult, background: np.ndarray, fig: ReportFigures
) -> None:
    """Left: the image with the circle, the outer band, every used corner and its residual."""
    size = 760
    h, w = background.shape[:2]
    s = size / max(w, h)
    bg = cv2.resize(background, (round(w * s), round(h * s)), interpolation=cv2.INTER_AREA)
    bg = cv2.cvtColor((bg * 0.45).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    x0, y0 = 20, 60
    canvas[y0 : y0 + bg.shape[0], x0 : x0 + bg.shape[1]] = bg
    panel = canvas[y0 : y0 + bg.shape[0], x0 : x0 + bg.shape[1]]
    cu, cv_ = result.model.center_uv
    c = (round(cu * s), round(cv_ * s))
    cv2.circle(panel, c, round(fig.circle_radius_px * s), _GREY, 1, cv2.LINE_AA)
    cv2.circle(panel, c, round((1 - OUTER_BAND) * fig.circle_radius_px * s), _GREY, 1, cv2.LINE_AA)
    res = np.concatenate([result.residuals_px[n] for n in result.images_used])
    p95 = float(np.percentile(np.linalg.norm(res, axis=1), 95)) if len(res) else 1.0
    gain = 0.04 * size / max(p95, 1e-6)  # the 95th percentile residual draws 4 % of the panel
    for k, name in enumerate(result.images_used):
        hue = int(180 * k / max(len(result.images_used), 1))
        hsv = np.array([[[hue, 200, 255]]], np.uint8)
        col = cv2.cvtColor(hsv, cv2.COLOR_HSV2BGR)[0, 0].tolist()
        for p, r in zip(result.corners_px[name], result.residuals_px[name], strict=True):
            a = (round(p[0] * s), round(p[1] * s))
            b = (round(p[0] * s + r[0] * gain), round(p[1] * s + r[1] * gain))
            cv2.circle(panel, a, 2, col, -1, cv2.LINE_AA)
            cv2.line(panel, a, b, col, 1, cv2.LINE_AA)
    _put(canvas, "used corners and residual vectors", (x0, 30), scale=0.6)
    _put(
        canvas,
        f"residuals drawn x{gain / s:.0f} (95th percentile {p95:.2f} px); circles: image circle"
        f" r = {fig.circle_radius_px:.0f} px and its outer {OUTER_BAND:.0%}",
        (x0, 50),
        _GREY,
        0.42,
    )


def _radius_panel(canvas: np.ndarray, result: IntrinsicResult, fig: ReportFigures) -> None:
    """Top right: residual against radius (every corner, and the binned RMS)."""
    x0, y0, pw, ph = 860, 60, 700, 330
    cv2.rectangle(canvas, (x0, y0), (x0 + pw, y0 + ph), _GREY, 1)
    cu, cv_ = result.model.center_uv
    pts = np.concatenate([result.corners_px[n] for n in result.images_used])
    dist = np.linalg.norm(
        np.concatenate([result.residuals_px[n] for n in result.images_used]), axis=1
    )
    rho = np.hypot(pts[:, 0] - cu, pts[:, 1] - cv_)
    ymax = max(float(np.percentile(dist, 99.5)) * 1.1, 1e-3)
    rmax = max(fig.circle_radius_px, float(rho.max()))

    def to_xy(r: float, d: float) -> tuple[int, int]:
        return (round(x0 + pw * r / rmax), round(y0 + ph - ph * min(d, ymax) / ymax))

    for r, d in zip(rho, dist, strict=True):
        cv2.circle(canvas, to_xy(r, d), 1, (170, 120, 60), -1)
    line = [to_xy(r, rms) for r, rms, _ in fig.residual_by_radius]
    for a, b in itertools.pairwise(line):
        cv2.line(canvas, a, b, _AMBER, 2, cv2.LINE_AA)
    band = round(x0 + pw * (1 - OUTER_BAND) * fig.circle_radius_px / rmax)
    cv2.line(canvas, (band, y0), (band, y0 + ph), _GREY, 1)
    _put(
        canvas,
        "residual (px) against distance from the centre (px); amber: RMS per bin",
        (x0, 30),
        scale=0.6,
    )
    _put(canvas, f"{ymax:.2f}", (x0 - 45, y0 + 12), _GREY, 0.4)
    _put(canvas, "0", (x0 - 15, y0 + ph), _GREY, 0.4)
    _put(canvas, f"{rmax:.0f}", (x0 + pw - 30, y0 + ph + 18), _GREY, 0.4)
    _put(canvas, "outer band", (band + 4, y0 + 14), _GREY, 0.4)


def _text_panel(canvas: np.ndarray, result: IntrinsicResult, fig: ReportFigures) -> None:
    """Bottom right: summary, coverage (and its warning), per-image RMS, what was dropped."""
    x0, y = 860, 430
    m = result.model
    lines = [
        (
            f"RMS {result.rms_px:.3f} px over {len(result.images_used)} images, "
            f"{sum(len(v) for v in result.corners_px.values())} corners; polynomial degree "
            f"{result.degree}; centre {m.center_uv[0]:.1f}, {m.center_uv[1]:.1f}",
            _WHITE,
        ),
        (
            f"outer {OUTER_BAND:.0%} of the circle covered: {fig.outer_coverage:.0%} of "
            f"{fig.sectors_inside} sectors",
            _WHITE,
        ),
    ]
    if fig.warning:
        lines.append(("WARNING: " + fig.warning[:110], _RED))
    lines.append(("per image: RMS px, refinement, corners used", _GREY))
    for name in result.images_used:
        n = len(result.corners_px[name])
        how = result.refinement.get(name, "")
        lines.append(
            (f"  {result.per_image_rms_px[name]:6.3f}  {how:6s} {n:3d}  {_short(name)}", _WHITE)
        )
    for rej in result.images_rejected:
        lines.append((f"  dropped {_short(rej.name)}: {rej.reason}"[:120], _AMBER))
    by_image: dict[str, list[str]] = {}
    for cr in result.corners_rejected:
        by_image.setdefault(cr.name, []).append(f"#{cr.corner} {cr.reason}")
    for name, items in by_image.items():
        lines.append(
            (f"  {_short(name)}: {len(items)} corner(s) dropped: {items[0]}"[:120], _AMBER)
        )
    step = max(12, min(20, (_H - y - 10) // max(len(lines), 1)))
    for text, col in lines:
        if y > _H - 8:
            break
        _put(canvas, text, (x0, y), col, 0.42)
        y += step


def _short(name: str) -> str:
    return name.replace("\\", "/").rsplit("/", 1)[-1]


def build_report(
    result: IntrinsicResult, images: list[tuple[str, np.ndarray]]
) -> tuple[ReportFigures, np.ndarray]:
    """Figures and picture of a calibration from its images (grey or BGR)."""
    grays = [cv2.cvtColor(i, cv2.COLOR_BGR2GRAY) if i.ndim == 3 else i for _, i in images]
    size = (grays[0].shape[1], grays[0].shape[0])
    radius = image_circle_radius(grays, result.model.center_uv)
    figures = report_figures(result, size, radius)
    used = dict(zip([n for n, _ in images], grays, strict=True))
    background = used.get(result.images_used[0], grays[0]) if result.images_used else grays[0]
    return figures, render_report(result, background, figures)


def log_report(log: object, figures: ReportFigures, picture: np.ndarray) -> None:
    """The report picture and its numbers into the run's log (a RunLog)."""
    log.image("intrinsics/report", picture)  # type: ignore[attr-defined]
    log.scalar("intrinsics/outer_coverage", figures.outer_coverage)  # type: ignore[attr-defined]
    if figures.warning:
        log.event("intrinsics/warnings", figures.warning, level="WARN")  # type: ignore[attr-defined]
