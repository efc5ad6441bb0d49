""" "No laser here" is a result (`core.laser_presence`): a spot, a coloured mark or a defocused
patch of light gives no stripe points, and a line, through the colour camera's effects as
well, keeps every piece the extractor found. (The cell's own path, on/off differences of the
cluttered sorting cell through the same effects with a dark laser, is a typed error:
tests/pipeline/test_measurement_capture.py.)

The synthetic pictures are those of tests/core/test_laser_stripe.py (a Gaussian red ridge of
sigma 1.2 px on grey with 2 grey levels of noise), at 480 px: scan lines 1 px apart, so a line
needs 16 px."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.core.laser_presence import (
    MAX_LINE_SCATTER_PX,
    MIN_LINE_SCANS,
    chain_shapes,
    line_presence,
)
from omnisort_hw.core.laser_stripe import laser_stripe_points_stats
from tests.core.test_laser_stripe import SIZE, background, draw_line, to_u8
from tests.sim.image_measures import distance_to_lines


def red_spot(img: np.ndarray, centre: tuple[float, float], radius_px: float) -> np.ndarray:
    """A small red Gaussian spot (an LED, a coloured mark) added to a float image."""
    v, u = np.mgrid[0:SIZE, 0:SIZE].astype(float)
    spot = np.exp(-0.5 * ((u - centre[0]) ** 2 + (v - centre[1]) ** 2) / radius_px**2)
    img[..., 2] += 140.0 * spot
    img[..., 1] -= 40.0 * spot
    img[..., 0] -= 40.0 * spot
    return img


def test_a_line_is_long_and_thin_a_patch_is_not() -> None:
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 80.0, 2.0)
    line = np.column_stack([100 + t, 50 + 0.3 * t + rng.normal(0, 0.1, t.size)])
    angle, radius = rng.uniform(0, 2 * np.pi, 60), 16 * np.sqrt(rng.uniform(0, 1, 60))
    patch = np.column_stack([300 + radius * np.cos(angle), 300 + radius * np.sin(angle)])
    points = np.concatenate([line, patch, [[10.0, 10.0], [12.0, 10.0], [14.0, 11.0]]])
    chains = np.repeat([3, 8, 9], [len(line), len(patch), 3])
    labels, length, scatter = chain_shapes(points, chains)
    assert labels.tolist() == [3, 8, 9]
    assert length[0] == pytest.approx(np.hypot(78, 0.3 * 78), abs=1.0)
    # The speckle grains of a 32 px patch of light: as long as a line, not as thin.
    assert scatter[0] < 0.3 and scatter[1] > MAX_LINE_SCATTER_PX and length[1] > 16
    assert np.isinf(scatter[2])  # too few points to have a local line
    presence = line_presence(points, chains, 1)
    assert presence.present and presence.chains == 3
    assert (presence.spots, presence.blobs) == (1, 1)
    alone = line_presence(points[len(line) :], chains[len(line) :], 1)
    assert not alone.present and "no laser line" in alone.reason()


def test_a_spot_or_a_mark_gives_no_points_and_says_why() -> None:
    img = red_spot(background(4), (200.0, 150.0), 2.0)
    img = red_spot(img, (320.0, 330.0), 3.0)
    pts, stats = laser_stripe_points_stats(to_u8(img))
    assert len(pts) == 0 and stats.points == 0
    assert stats.presence is not None and not stats.presence.present
    assert stats.presence.spots >= 1 and stats.presence.min_line_px == MIN_LINE_SCANS
    assert "shorter than a line's 16 px" in stats.presence.reason()


def test_with_a_line_the_spots_beside_it_stay() -> None:
    """The rule judges the image, not each piece: a short piece of a line on a small object is
    kept once the image shows a line."""
    line = ((100.3, 40.0), (160.7, 440.0))
    img = red_spot(draw_line(background(5), *line), (350.0, 200.0), 2.0)
    pts, stats = laser_stripe_points_stats(to_u8(img))
    assert stats.presence is not None and stats.presence.present
    assert stats.presence.longest_line_px > 300
    near_spot = np.hypot(pts[:, 0] - 350.0, pts[:, 1] - 200.0) < 8
    assert near_spot.any()


def effects(name: str) -> object:
    """The shipped scene at 480 px through the sensor with the colour camera's effects
    (crosstalk, chromatic aberration, bloom, Bayer demosaicing)."""
    from sim_backend.scene import load_scene, sized, with_camera_effects

    return with_camera_effects(sized(load_scene(name), SIZE))


def test_a_laser_line_through_a_real_camera_is_still_a_line() -> None:
    """The two-sided target lit by the laser, through the same effects: a line, on its truth."""
    from sim_backend.scene_images import render_scene

    on, truth = render_scene(effects("two_sided"), seed=14)
    pts, stats = laser_stripe_points_stats(on)
    assert stats.presence is not None and stats.presence.present, stats.presence
    near = distance_to_lines(pts, truth["laser_polylines_px"])
    assert len(pts) >= 2 * MIN_LINE_SCANS and np.median(near) < 0.5, (len(pts), np.median(near))
