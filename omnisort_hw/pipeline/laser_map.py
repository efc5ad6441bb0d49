"""Laser map: the stripe's pixels -> points on the laser plane (S, mm) -> straight segments.

One use case for the CLI (`omnisort map`) and the service (`map`): `run(rig, MapRequest)`,
logged the same way.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.laser_echoes import direct_hits, floor_echoes
from omnisort_hw.core.laser_presence import LinePresence
from omnisort_hw.core.laser_stripe import laser_stripe_points_stats, stripe_interior
from omnisort_hw.core.map_uncertainty import (
    PointSigmas,
    point_sigmas,
    sigma_colours,
    stripe_pixel_sigma,
)
from omnisort_hw.core.mapping import Segment, pixels_to_plane, segments
from omnisort_hw.core.overlays import draw_map, write_picture
from omnisort_hw.core.records import PictureReply
from omnisort_hw.pipeline.cell_acquisition import acquire
from omnisort_hw.pipeline.image_files import check_image_size
from omnisort_hw.pipeline.replies import MapReply, MapSummary
from omnisort_hw.pipeline.requests import MapRequest
from omnisort_hw.pipeline.rig import Rig, raise_if_cancelled
from omnisort_hw.pipeline.verdict import Check, Verdict, at_least
from omnisort_hw.runlog import NullLog, RunLog


@dataclass
class LaserMap:
    """The stripe's pixels, their points on the laser plane (NaN where a ray misses it) and
    the segments fitted to the points."""

    pixels: np.ndarray
    points_S: np.ndarray
    segments: list[Segment]
    echoes: int = 0  # stripe points dropped as reflections (core.laser_echoes)
    ends: int = 0  # stripe points dropped at ends and kinks (core.laser_stripe.stripe_interior)
    sigmas: PointSigmas | None = None  # each point's uncertainty (core.map_uncertainty)
    laser_line: LinePresence | None = None  # whether the image showed a laser line at all

    @property
    def finite_points_S(self) -> np.ndarray:
        return self.points_S[np.all(np.isfinite(self.points_S), axis=1)]

    def summary(self, with_points: bool = False) -> MapSummary:
        """Counts and segments; `with_points` adds every point on the plane (S, 0.1 mm) and,
        in the same order, its pixel (0.01 px) and its standard deviations (0.01 mm) along
        the surface normal, along the line and off the laser plane."""
        finite = np.all(np.isfinite(self.points_S), axis=1)
        sg = self.sigmas if with_points else None

        def rounded(values: np.ndarray, digits: int) -> list[Any]:
            return np.round(values[finite], digits).tolist()

        return MapSummary(
            points=len(self.pixels),
            points_on_plane=int(finite.sum()),
            echoes_dropped=self.echoes,
            stripe_ends_dropped=self.ends,
            segments=[seg.summary() for seg in self.segments],
            sigma=self.sigmas.summary() if self.sigmas is not None else None,
            laser_line=self.laser_line.to_dict() if self.laser_line is not None else None,
            points_S=rounded(self.points_S, 1) if with_points else None,
            pixels=rounded(self.pixels, 2) if with_points else None,
            sigma_normal_mm=rounded(sg.normal_mm, 2) if sg is not None else None,
            sigma_along_mm=rounded(sg.along_mm, 2) if sg is not None else None,
            sigma_off_plane_mm=rounded(sg.off_plane_mm, 2) if sg is not None else None,
        )


def map_laser(
    image: np.ndarray,
    calib: SystemCalibration,
    source: str = "image",
    log: RunLog = NullLog,
    floor_S: tuple[np.ndarray, float] | None = None,
    light_only: bool = False,
    with_sigmas: bool = True,
    color: str = "red",
) -> LaserMap:
    """The laser map of one laser-on image (or a capture's laser-light image; its size must
    match the camera model). Points at the stripe's ends and kinks, where the straight-stripe
    fit is biased, are dropped where their piece has interior points; points that cannot be
    direct hits of the laser (a reflection at the same bearing, weaker, at another range; with
    the floor known, `floor_S` = (unit normal up, k) of n . x = k in S, the floor's mirror image
    of a stripe point seen) are dropped. `light_only`: the image is a capture's laser light
    alone (on minus off), whose centres are fitted on the red channel (`laser_stripe_points`).
    `with_sigmas`: every point's uncertainty too (core.map_uncertainty). `color`: the laser's."""
    check_image_size(image, calib.model, source)
    pixels, stats = laser_stripe_points_stats(image, light_only=light_only, color=color)
    interior = stripe_interior(stats)
    assert stats.heights is not None
    every = pixels_to_plane(pixels, calib)
    pixels, points, heights = pixels[interior], every[interior], stats.heights[interior]
    keep = direct_hits(points, heights)
    if floor_S is not None:
        n, k = floor_S
        keep &= ~floor_echoes(points, calib.laser_normal, calib.laser_distance_mm, n, k, every)
    pixels, points = pixels[keep], points[keep]
    sigmas = None
    if with_sigmas:
        chains = None if stats.chains is None else stats.chains[interior][keep]
        sigmas = point_sigmas(pixels, calib, stripe_pixel_sigma(pixels, chains), points)
    result = LaserMap(
        pixels,
        points,
        segments(points, calib, pixels=pixels),
        int((~keep).sum()),
        int((~interior).sum()),
        sigmas,
        stats.presence,
    )
    log.image("map/image", image)
    log.points2d("map/image/laser", pixels, color=(255, 0, 0), radius=1)
    if sigmas is None:
        log.points3d("map/points_S", result.finite_points_S, color=(255, 0, 0))
    else:
        finite = np.all(np.isfinite(points), axis=1)
        log.points3d("map/points_S", points[finite], color=sigma_colours(sigmas.normal_mm[finite]))
        if np.isfinite(sigmas.normal_mm).any():
            log.scalar("map/sigma_normal_mm_median", float(np.nanmedian(sigmas.normal_mm)))
    for i, seg in enumerate(result.segments):
        log.points3d(f"map/segments/{i}", seg.points_S, color=(0, 200, 255))
    return result


def map_overlay(
    image: np.ndarray, laser_map: LaserMap, calib: SystemCalibration, title: str = ""
) -> np.ndarray:
    """The map's picture: the image with its laser points beside their top view on the laser
    plane (mm), segments in matching colours. Drawn only when asked: `map_laser` stays fast."""
    sigma = None if laser_map.sigmas is None else laser_map.sigmas.normal_mm
    return draw_map(
        image, laser_map.pixels, laser_map.points_S, laser_map.segments, calib, title, sigma
    )


def floor_plane_S(
    calib: SystemCalibration, sort_config: Any = None
) -> tuple[np.ndarray, float] | None:
    """The floor as (unit normal up, k) of n . x = k in S, from the registered robot base
    (`robot_base` in system.json: B's z is up) and the floor's height in B (`[sorting]`
    floor_z_B_mm, 0 without it); None when the robot is not registered."""
    rb = calib.robot_base
    if not isinstance(rb, dict) or "matrix" not in rb:
        return None
    T = np.asarray(rb["matrix"], float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return None
    return floor_plane(T, float(getattr(sort_config, "floor_z_B_mm", 0.0) or 0.0))


def floor_plane(T_SB: np.ndarray, floor_z_B_mm: float = 0.0) -> tuple[np.ndarray, float]:
    """The floor as (unit normal up, k) of n . x = k in S, of the robot base `T_SB` (4x4, mm;
    B's z up) with the floor at `floor_z_B_mm` in B."""
    n = T_SB[:3, 2] / np.linalg.norm(T_SB[:3, 2])
    return n, float(n @ T_SB[:3, 3] + floor_z_B_mm)


@dataclass
class MapResult:
    """A map and what it was made from: the image's (or capture's) record and its picture."""

    laser_map: LaserMap
    image: dict[str, Any]
    picture: PictureReply = field(default_factory=lambda: PictureReply())
    with_points: bool = False  # the request's `points`: the reply carries every point

    def reply(self) -> MapReply:
        """The answer at every door (the service's reply, the CLI's `--json`)."""
        summary = self.laser_map.summary(self.with_points)
        return MapReply(
            **vars(summary), **vars(self.picture), image=self.image, verdict=self.verdict()
        )

    def verdict(self) -> Verdict:
        """No laser line in the image is a FAIL: nothing is measured on phantom points (the
        light of spots, coloured marks, defocused patches; `core.laser_presence`). A map with
        a line but no segment maps nothing: its line falls on no surface in view, a WARN."""
        n_points = len(self.laser_map.pixels)
        line = self.laser_map.laser_line
        checks = []
        if line is not None:
            checks.append(
                Check(
                    "laser line",
                    "pass" if line.present else "fail",
                    f"{line.longest_line_px:.0f} px",
                    f">= {line.min_line_px:.0f} px long and thin",
                    "" if line.present else f"{line.reason()}: is the laser on and in view?",
                )
            )
        advice = (
            f"nothing was mapped ({n_points} laser points, none forming a segment): is the "
            "laser on, and does its line fall on a surface in view?"
        )
        checks.append(at_least("segments", len(self.laser_map.segments), 1, "warn", advice))
        return Verdict("laser map", tuple(checks))


def run(rig: Rig, request: MapRequest, cancel: threading.Event | None = None) -> MapResult:
    """The map of the request's image, or of a measurement capture's laser light, with the
    rig's calibration; the floor's mirror images (from the registered robot base and
    `[sorting]`) dropped; its picture written where the rig keeps it when asked."""
    calib = rig.system_calibration()
    acq = acquire(rig, request.image, board=False)
    raise_if_cancelled(cancel, "mapping")
    stripe = acq.stripe if acq.stripe is not None else acq.board
    floor = floor_plane_S(calib, rig.sort_config)
    light = acq.stripe_px is not None  # a capture's laser light: red-channel centres
    laser_map = map_laser(
        stripe, calib, acq.source, rig.runlog, floor, light_only=light, color=rig.laser_color()
    )
    result = MapResult(laser_map, acq.record, with_points=request.points)
    if request.picture:
        result.picture = write_picture(
            rig.picture_path("map", request.image),
            lambda: map_overlay(acq.board, laser_map, calib, acq.source),
        )
    return result
