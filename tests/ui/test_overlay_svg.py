"""The live view's overlays: the service's pixels scaled to the picture, the points coloured
by their sigma, a long map thinned to at most MAX_POINTS, nothing drawn without pixels."""

from __future__ import annotations

import re

from omnisort_hw.core.records import CubeReply
from omnisort_hw.pipeline.replies import (
    DetectReply,
    LayerReply,
    LocateReply,
    MapReply,
    VerdictReply,
)
from omnisort_hw.ui.overlay_svg import (
    MAX_POINTS,
    cubes_overlay,
    detection_overlay,
    map_overlay,
    sigma_colour,
)


def test_sigma_colours_run_from_green_to_red() -> None:
    assert sigma_colour(0.1, 0.1, 0.5) == "#00ff00"
    assert sigma_colour(0.3, 0.1, 0.5) == "#ffff00"
    assert sigma_colour(0.5, 0.1, 0.5) == "#ff0000"
    assert sigma_colour(9.0, 0.1, 0.5) == "#ff0000"  # beyond the range: red
    assert sigma_colour(0.2, 0.2, 0.2) == "#00ff00"  # one value: no range


def _map(pixels: list[list[float]] | None, sigma: list[float] | None) -> MapReply:
    """A map's reply with these pixels and sigmas (None: a map asked without points)."""
    verdict = VerdictReply("laser map", ())
    return MapReply(
        points=len(pixels or []),
        points_on_plane=len(pixels or []),
        echoes_dropped=0,
        stripe_ends_dropped=0,
        segments=[],
        pixels=pixels,
        sigma_normal_mm=sigma,
        image={},
        verdict=verdict,
    )


def _cube(color: str, center_px: list[float] | None, ellipse_px: list[list[float]] | None,
          sigma_mm: float = 0.0, ellipse_scale: float | None = None) -> CubeReply:  # fmt: skip
    return CubeReply(
        color, [0.0] * 3, [0.0] * 3, 0.0, 0.0, sigma_mm, [0.0, 0.0], [0.0, 0.0], 0.0, 0.0,
        100, 50, 0, [], center_px=center_px, ellipse_px=ellipse_px, ellipse_scale=ellipse_scale,
    )  # fmt: skip


def _located(*cubes: CubeReply) -> LocateReply:
    return LocateReply(
        cubes=list(cubes), count=len(cubes), rejected=[], verdict=VerdictReply("locate", ())
    )


def test_map_points_are_scaled_and_thinned() -> None:
    n = 2 * MAX_POINTS + 1
    overlay = map_overlay(_map([[2.0 * i, 10.0] for i in range(n)], [0.1] * n), 0.5)
    assert overlay is not None
    xs = [float(x) for x in re.findall(r'cx="([\d.]+)"', overlay.svg)]
    assert len(xs) <= MAX_POINTS and len(xs) >= MAX_POINTS // 2
    assert xs[0] == 0.0 and xs[1] == 3.0  # every 3rd point, camera px times 0.5
    assert set(re.findall(r'cy="([\d.]+)"', overlay.svg)) == {"5.0"}
    assert f"{n} laser points" in overlay.legend and "1 in 3 drawn" in overlay.legend


def test_no_overlay_without_pixels() -> None:
    assert map_overlay(_map(None, None), 1.0) is None  # a map asked without points
    assert map_overlay(_map([[1, 2]], []), 1.0) is None
    assert map_overlay(None, 1.0) is None and cubes_overlay(None, 1.0) is None
    assert cubes_overlay(_located(_cube("red", None, None)), 1.0) is None


def test_cubes_are_drawn_in_their_colour_with_their_index() -> None:
    ring = [[10.0, 0.0], [0.0, 10.0], [-10.0, 0.0]]
    reply = _located(
        _cube("red", [100, 50], ring, sigma_mm=1.234, ellipse_scale=10.0),
        _cube("<script>", [10, 10], ring),
    )
    overlay = cubes_overlay(reply, 2.0)
    assert overlay is not None
    assert 'stroke="red"' in overlay.svg and "<script>" not in overlay.svg
    assert 'points="20.0,0.0 0.0,20.0 -20.0,0.0"' in overlay.svg
    assert '<text x="200.0" y="100.0"' in overlay.svg and 'font-size="16.0"' in overlay.svg
    small = cubes_overlay(reply, 2.0, unit=0.5)
    assert small is not None and 'font-size="8.0"' in small.svg
    assert "drawn x10" in overlay.legend and "0 red sigma 1.23 mm" in overlay.legend


def test_a_detection_is_drawn_layer_by_layer_in_its_colours() -> None:
    def found(*layers: LayerReply) -> DetectReply:
        summary = "the two-sided target found: 2 border px, 2 markers"
        return DetectReply("target", "two-sided", True, summary, 640, 480, list(layers))

    reply = found(
        LayerReply("left wall border", "border", "#ffff00", [[10.0, 20.0], [12.0, 22.0]]),
        LayerReply(
            "left wall markers",
            "marker",
            "#0050ff",
            [[100.0, 50.0], [200.0, 60.0]],
            labels=["L:border_near", "L:<far>"],
        ),
    )
    overlay = detection_overlay(reply, 0.5)
    rings = re.findall(r'<circle cx="([\d.]+)" cy="([\d.]+)" r="8.00" fill="none" '
                       r'stroke="#0050ff"', overlay.svg)  # fmt: skip
    assert rings == [("50.0", "25.0"), ("100.0", "30.0")]  # camera px times the picture's scale
    dots = re.findall(r'<circle cx="([\d.]+)" cy="([\d.]+)" r="1.50" fill="#ffff00"', overlay.svg)
    assert dots == [("5.0", "10.0"), ("6.0", "11.0")]
    assert "L:border_near" in overlay.svg and "L:&lt;far&gt;" in overlay.svg  # escaped
    assert overlay.legend == reply.summary
    assert detection_overlay(found(), 1.0).svg == ""
