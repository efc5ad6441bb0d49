"""The live view's overlays as SVG, from replies the service gave: the last map's laser points
coloured by their sigma, and the last located cubes with their position ellipses. Nothing is
computed here but scaling: the pixels are the service's (`map` with points, `locate`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape

from omnisort_hw.pipeline.replies import DetectReply, LocateReply, MapReply, ViewsReply

MAX_POINTS = 800  # drawn of a map's points, evenly spaced: enough to see, light to send


@dataclass(frozen=True)
class Overlay:
    """An SVG fragment in the picture's pixels, and its legend for people."""

    svg: str
    legend: str


def sigma_rgb(sigma: float, lo: float, hi: float) -> tuple[float, float, float]:
    """Green at `lo`, through yellow, to red at `hi` and beyond: (r, g, b) in [0, 1]."""
    t = 0.0 if hi <= lo else min(1.0, max(0.0, (sigma - lo) / (hi - lo)))
    return (min(1.0, 2.0 * t), min(1.0, 2.0 * (1.0 - t)), 0.0)


def sigma_colour(sigma: float, lo: float, hi: float) -> str:
    """`sigma_rgb` as a CSS colour."""
    red, green, _ = sigma_rgb(sigma, lo, hi)
    return f"#{round(255 * red):02x}{round(255 * green):02x}00"


def map_overlay(reply: MapReply | None, scale: float, unit: float = 1.0) -> Overlay | None:
    """The map's points (`pixels`, camera px) coloured by `sigma_normal_mm`; None without
    points (a map asked without `points`). `unit`: the picture's px per px of a 960 px one
    (marks keep their size on the screen whatever the picture's)."""
    pixels = (reply.pixels if reply is not None else None) or []
    sigma = (reply.sigma_normal_mm if reply is not None else None) or []
    if not pixels or len(sigma) != len(pixels):
        return None
    step = max(1, -(-len(pixels) // MAX_POINTS))
    lo, hi = min(sigma), max(sigma)
    dots = "".join(
        f'<circle cx="{u * scale:.1f}" cy="{v * scale:.1f}" r="{2 * unit:.2f}" '
        f'fill="{sigma_colour(s, lo, hi)}" />'
        for (u, v), s in zip(pixels[::step], sigma[::step], strict=True)
    )
    legend = (
        f"{len(pixels)} laser points, sigma across the plane {lo:.2f} mm (green) "
        f"to {hi:.2f} mm (red)" + (f", 1 in {step} drawn" if step > 1 else "")
    )
    return Overlay(dots, legend)


def cubes_overlay(reply: LocateReply | None, scale: float, unit: float = 1.0) -> Overlay | None:
    """Each located cube: its ellipse (`ellipse_px`, enlarged as `ellipse_scale` says) in its
    colour, and its index at its centre; None when the reply has no cube pixels."""
    shown = [
        (c, c.center_px, c.ellipse_px)
        for c in (reply.cubes if reply is not None else [])
        if c.center_px and c.ellipse_px
    ]
    if not shown:
        return None
    parts = []
    for i, (cube, centre, ellipse) in enumerate(shown):
        colour = escape(cube.color)
        ring = " ".join(f"{u * scale:.1f},{v * scale:.1f}" for u, v in ellipse)
        u, v = (c * scale for c in centre)
        parts.append(
            f'<polygon points="{ring}" fill="none" stroke="black" stroke-width="{4 * unit:.2f}" />'
            f'<polygon points="{ring}" fill="none" stroke="{colour}" '
            f'stroke-width="{2 * unit:.2f}" />'
            f'<text x="{u:.1f}" y="{v:.1f}" fill="white" stroke="black" '
            f'stroke-width="{0.6 * unit:.2f}" font-size="{16 * unit:.1f}" font-weight="bold" '
            f'text-anchor="middle">{i}</text>'
        )
    enlarge = shown[0][0].ellipse_scale or 1
    legend = f"{len(shown)} cubes: 95 % position ellipse drawn x{enlarge:g}, " + ", ".join(
        f"{i} {c.color} sigma {c.sigma_mm:.2f} mm" for i, (c, _, _) in enumerate(shown)
    )
    return Overlay("".join(parts), legend)


def detection_overlay(reply: DetectReply, scale: float, unit: float = 1.0) -> Overlay:
    """A `detect` reply's layers in their colours: markers ringed and labelled, board corners
    and rejected corners as larger dots, border, floor line and stripe as small dots."""
    parts = []
    for layer in reply.layers:
        colour = escape(layer.colour)
        labels = layer.labels or []
        if layer.kind == "marker":
            for i, (u, v) in enumerate(layer.pixels):
                x, y = u * scale, v * scale
                parts.append(
                    f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{8 * unit:.2f}" fill="none" '
                    f'stroke="{colour}" stroke-width="{2 * unit:.2f}" />'
                )
                if i < len(labels):
                    parts.append(
                        f'<text x="{x + 10 * unit:.1f}" y="{y:.1f}" fill="{colour}" '
                        f'font-size="{12 * unit:.1f}">{escape(labels[i])}</text>'
                    )
            continue
        r = (3 if layer.kind in ("corner", "rejected") else 1.5) * unit
        parts += [
            f'<circle cx="{u * scale:.1f}" cy="{v * scale:.1f}" r="{r:.2f}" fill="{colour}" />'
            for u, v in layer.pixels
        ]
    return Overlay("".join(parts), reply.summary)


def coverage_overlay(reply: ViewsReply, scale: float, unit: float = 1.0) -> Overlay | None:
    """A `views` reply over the picture: the image circle's outer band, each of its sectors
    green where a view's corners reach it and red where none does yet (sectors outside the
    frame not drawn), and every kept view's board outline; None without views."""
    cov = reply.coverage
    if cov is None:
        return None
    cu, cv = (c * scale for c in cov.centre_px)
    r_out = cov.radius_px * scale
    r_in = (1.0 - cov.outer_band) * r_out
    n = len(cov.covered)
    parts = []
    for k, (covered, inside) in enumerate(zip(cov.covered, cov.inside, strict=True)):
        if not inside:
            continue
        a0, a1 = -math.pi + 2 * math.pi * k / n, -math.pi + 2 * math.pi * (k + 1) / n
        p = [(cu + r * math.cos(a), cv + r * math.sin(a)) for r, a in
             ((r_out, a0), (r_out, a1), (r_in, a1), (r_in, a0))]  # fmt: skip
        colour = "#22c55e" if covered else "#ef4444"
        parts.append(
            f'<path d="M {p[0][0]:.1f} {p[0][1]:.1f} A {r_out:.1f} {r_out:.1f} 0 0 1 '
            f"{p[1][0]:.1f} {p[1][1]:.1f} L {p[2][0]:.1f} {p[2][1]:.1f} A {r_in:.1f} {r_in:.1f} "
            f'0 0 0 {p[3][0]:.1f} {p[3][1]:.1f} Z" fill="{colour}" fill-opacity="0.35" '
            f'data-covered="{str(bool(covered)).lower()}" />'
        )
    for view in reply.views:
        ring = " ".join(f"{u * scale:.1f},{v * scale:.1f}" for u, v in view.outline_px)
        parts.append(
            f'<polygon points="{ring}" fill="none" stroke="#38bdf8" '
            f'stroke-width="{1.5 * unit:.2f}" />'
        )
    legend = (
        f"{reply.count} views; the image circle's rim covered "
        f"{cov.fraction:.0%} (green: reached by a view's corners, red: not yet)"
    )
    return Overlay("".join(parts), legend)
