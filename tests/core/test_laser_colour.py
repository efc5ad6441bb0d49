"""A green or a blue line laser is found as a red one is (`laser_stripe_points(color=...)`):
the channels are reordered so the laser's plays red, and the rest of the extractor, tuned and
measured on red, is the same. Renders of the two-sided target with each colour: the points lie
on the true line, and the extractor told the wrong colour finds next to nothing."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.errors import InputError
from sim_backend.scene import Color, load_scene, sized
from sim_backend.scene_images import render_scene
from tests.sim.image_measures import distance_to_lines

# Each colour as the shipped red laser is drawn: the main channel full, the others faint.
LASERS = {
    "red": (1.0, 0.06, 0.04),
    "green": (0.06, 1.0, 0.04),
    "blue": (0.04, 0.06, 1.0),
}


@pytest.fixture(scope="module")
def renders() -> dict[str, tuple[np.ndarray, dict]]:
    base = sized(load_scene("two_sided"), 480)
    out = {}
    for name, rgb in LASERS.items():
        scene = base.replace(laser={"color": Color(name, rgb)})
        out[name] = render_scene(scene)
    return out


@pytest.mark.parametrize("color", list(LASERS))
def test_each_laser_colour_is_found_on_its_line(renders, color: str) -> None:
    image, truth = renders[color]
    pts = laser_stripe_points(image, color=color)
    reference = laser_stripe_points(renders["red"][0])  # the red laser, as tuned
    assert len(pts) >= 0.8 * len(reference), (len(pts), len(reference))
    d = distance_to_lines(pts, truth["laser_polylines_px"])
    # The renderer draws the stripe within 0.5 px of the truth's line (test_render); the
    # extractor's centres scatter a few tenths about it.
    assert np.median(d) <= 0.5 and np.percentile(d, 95) <= 1.5, np.percentile(d, [50, 95])
    others = [c for c in LASERS if c != color]
    wrong = max(len(laser_stripe_points(image, color=c)) for c in others)
    assert wrong <= 0.1 * len(pts), (color, wrong, len(pts))


def test_an_unknown_colour_is_refused_by_name(renders) -> None:
    with pytest.raises(InputError, match="laser color: 'violet'"):
        laser_stripe_points(renders["red"][0], color="violet")
