"""The real-light yardstick (`evaluation.real_stripe`) on a synthetic photograph whose stripe
is known: a checkerboard card and a wide red line whose core clips to white through the colour
filters' crosstalk, as on the real photographs. The reference finds the true centre line, the
clipped run's centre and the board; `judge` counts points on a flank as off and a line
measured on both flanks as split."""

from __future__ import annotations

import numpy as np
import pytest

from omnisort_hw.evaluation.real_stripe import board_hull, judge, reference_stripe

W, H = 640, 480
SIGMA = 4.0  # px: the stripe's Gaussian profile
PEAK = 600.0  # grey levels of laser light at the centre: the core clips over ~5 px
CROSSTALK = 0.45  # of the red light that green and blue see
SQUARE = 40


def _truth(u: np.ndarray) -> np.ndarray:
    """The true centre line v(u): gently bent, as a lens bends a plane's line, and inside one
    row of squares (120 <= v < 160) with its flanks: where the paper under one flank is
    brighter, that flank clips sooner and the clipped run is no longer centred."""
    return 140.0 + 0.01 * (u - 320.0) + 3e-5 * (u - 320.0) ** 2


def _photo(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:H, 0:W].astype(float)
    board = ((u - 100) // SQUARE + (v - 80) // SQUARE) % 2 == 0
    inside = (u >= 100) & (u < 100 + 11 * SQUARE) & (v >= 80) & (v < 80 + 8 * SQUARE)
    grey = np.where(inside & board, 30.0, 190.0)
    laser = PEAK * np.exp(-0.5 * ((v - _truth(u)) / SIGMA) ** 2)
    bgr = np.stack([grey + CROSSTALK * laser, grey + CROSSTALK * laser, grey + laser], axis=2)
    bgr += rng.normal(0.0, 2.0, bgr.shape)
    return np.clip(np.rint(bgr), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    return _photo()


def test_the_reference_is_the_true_centre_line_and_the_clipped_runs_centre(
    photo: np.ndarray,
) -> None:
    ref = reference_stripe(photo, "red")
    assert ref is not None and not ref.steep
    # The yardstick judges points at 2 px or more off (`tol`): its own errors stay under an
    # eighth of that per line, and far under on the fitted line.
    err = ref.centre - _truth(ref.lines.astype(float))
    assert float(np.sqrt(np.mean(err**2))) < 0.25, err
    line = ref.line(ref.lines.astype(float)) - _truth(ref.lines.astype(float))
    assert float(np.max(np.abs(line))) < 0.15
    clipped = np.isfinite(ref.clip_centre)
    assert clipped.mean() > 0.9  # the core clips on white and on black squares alike
    clip_err = ref.clip_centre[clipped] - _truth(ref.lines[clipped].astype(float))
    # the run's ends in whole samples, each of which noise may flip: a pixel at most
    assert float(np.max(np.abs(clip_err))) <= 1.0, clip_err


def test_judge_counts_flank_points_as_off_and_split(photo: np.ndarray) -> None:
    ref = reference_stripe(photo, "red")
    hull = board_hull(photo)
    assert ref is not None and hull is not None
    # The board: 10 x 7 inner corners grown by a square, about the checkered area.
    lo, hi = hull.min(axis=0), hull.max(axis=0)
    assert np.allclose(lo, (100, 80), atol=2) and np.allclose(hi, (540, 400), atol=2), hull
    u = np.arange(20.0, 620.0, 2.0)
    on = np.stack([u, _truth(u)], axis=1)
    good = judge(ref, hull, on)
    assert good["off_on_board"] == 0.0 and good["coverage"] == 1.0, good
    assert good["clipped_median_px"] <= 0.5 and good["clipped_split"] == 0.0, good
    flank = 2.0 * SIGMA
    shift = np.array([0.0, flank])
    flanks = np.concatenate([on - shift, on + shift])
    split = judge(ref, hull, flanks)
    assert split["off_on_board"] == 1.0 and split["coverage"] == 0.0, split
    assert split["clipped_split"] == 1.0 and split["clipped_median_px"] > flank - 1.0, split
    phantom = np.array([[300.0, 350.0], [320.0, 352.0]])  # on the board, off the stripe
    some = judge(ref, hull, np.concatenate([on, phantom]))
    n_board = some["points_on_board"]
    assert some["off_on_board"] == pytest.approx(2 / n_board, abs=1e-4), some  # 4 decimals
    # No point at all (an extractor that saw no laser line): nothing covered, nothing off.
    none = judge(ref, hull, np.zeros((0, 2)))
    assert none["points"] == 0 and none["coverage"] == 0.0 and none["off_on_board"] is None


def test_no_laser_line_gives_no_reference() -> None:
    rng = np.random.default_rng(1)
    v, u = np.mgrid[0:H, 0:W]
    board = (((u // SQUARE) + (v // SQUARE)) % 2 == 0)[..., None]
    bgr = np.where(board, 40, 200) + rng.normal(0.0, 2.0, (H, W, 3))
    assert reference_stripe(np.clip(bgr, 0, 255).astype(np.uint8), "red") is None
