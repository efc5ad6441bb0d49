"""Cube location: the cubes in a colour image (and a laser-on image), in S and in B.

One use case for the CLI (`omnisort locate`) and the service (`locate`), `run(rig,
LocateRequest)`, and a step of the sorting run: the
`[sorting]` record gives the cube size, the colours, the search region and the floor height,
the calibration gives the camera, the laser plane and the robot base; the floor board's area
is left out (its squares are not cubes).
"""

from __future__ import annotations

import json
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from omnisort_hw.core.cell_pictures import cube_pixels, draw_cubes
from omnisort_hw.core.cube_location import Cube, LocateSettings, locate_cubes
from omnisort_hw.core.cube_uncertainty import add_calibration_part, rotation_covariance
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.core.mapping import pixels_to_plane
from omnisort_hw.core.overlays import write_picture
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.core.records import CubeReply, PictureReply
from omnisort_hw.core.registration import Registration
from omnisort_hw.errors import NotAvailableError
from omnisort_hw.pipeline.calibration_source import robot_base_T
from omnisort_hw.pipeline.cell_acquisition import acquire
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.pipeline.replies import LocateReply
from omnisort_hw.pipeline.requests import LocateRequest
from omnisort_hw.pipeline.rig import Rig, raise_if_cancelled
from omnisort_hw.pipeline.verdict import Verdict, at_least, graded, verdict_lines
from omnisort_hw.runlog import NullLog, RunLog
from omnisort_hw.wire_records import to_wire


@dataclass
class Located:
    """The result of one capture + location: cubes and what was needed to find them."""

    cubes: list[Cube]
    T_SB: np.ndarray
    calib: SystemCalibration
    registration: Registration | None
    diagnostics: dict[str, Any]
    image: np.ndarray = field(repr=False)


@dataclass
class LocateResult:
    """The cubes found and what was left out (the location's `rejected` blobs)."""

    cubes: list[Cube]
    diagnostics: dict[str, Any] = field(repr=False)
    max_sigma_mm: float = SortConfig.max_sigma_mm
    picture: PictureReply = field(default_factory=lambda: PictureReply())
    colors: tuple[str, ...] | None = None  # the request's: the reply gives only these
    shown: list[CubeReply] = field(default_factory=list)  # each cube with its pixels

    def lines(self) -> list[str]:
        """The location in a few lines for people (the picture's legend, the CLI)."""
        out = [f"{len(self.cubes)} cubes"]
        for i, c in enumerate(self.cubes):
            x, y, z = c.center_B
            out.append(
                f"{i} {c.color}: B ({x:.1f}, {y:.1f}, {z:.1f}) mm, yaw {c.yaw_B_deg:.1f} deg, "
                f"sigma {c.sigma_mm:.2f} mm"
            )
        return [*out, *verdict_lines(self.verdict())]

    def asked(self) -> list[Cube]:
        """The cubes of the request's colours (all when it named none)."""
        return [c for c in self.cubes if self.colors is None or c.color in self.colors]

    def verdict(self) -> Verdict:
        """A cube located worse than `[sorting] max_sigma_mm` is skipped by a sort (its
        outline fit's own sigma, as the sort judges it); no cube is worth a look."""
        cubes = self.asked()
        found = at_least(
            "cubes", len(cubes), 1, "warn", "no cube found: look at the picture (light, colours)"
        )
        fits = [float(np.hypot(*c.sigma_xy_mm)) for c in cubes]
        worst = max(fits, default=0.0)
        uncertain = sum(not s <= self.max_sigma_mm for s in fits)
        sigma = graded(
            "worst outline fit sigma",
            worst,
            "mm",
            self.max_sigma_mm,
            advice=f"{uncertain} cube(s) would be skipped by a sort as too uncertain",
        )
        return Verdict("locate", (found, sigma) if cubes else (found,))

    def reply(self) -> LocateReply:
        """The answer at every door: the cubes (of the request's colours) with their pixels,
        their count, and the blobs rejected inside the search region with the reason."""
        where = {id(c): p for c, p in zip(self.cubes, self.shown, strict=False)}
        found = [where.get(id(c)) or c.summary() for c in self.asked()]
        rejected = [
            r
            for r in self.diagnostics.get("rejected", [])
            if r.reason != "outside the search region"
        ]
        return LocateReply(
            cubes=found,
            count=len(found),
            rejected=rejected,
            verdict=self.verdict(),
            **vars(self.picture),
        )


def run(rig: Rig, request: LocateRequest, cancel: threading.Event | None = None) -> LocateResult:
    """The cubes of the request's image (its laser-on image as height check when given), or of
    a measurement capture (its averaged laser-off image and its laser light) when `[sorting]`
    uses the laser and the rig has one, else of one laser-off frame."""
    cfg = rig.sort_config
    if cfg is None:
        raise NotAvailableError(
            "the colour-blob location needs a [sorting] section in the cell configuration "
            "(bins, obstacles, cube size, home pose; or from_scene = true)"
        )
    calib = rig.system_calibration()
    T_SB = robot_base_T(calib, str(rig.system_path), for_motion=False)
    laser_image: np.ndarray | None = None
    if request.image is not None:
        colour = read_image(request.image)
        if request.laser_image is not None:
            laser_image = read_image(request.laser_image)
    elif cfg.use_laser and rig.has_laser():
        acq = acquire(rig, None, board=True)
        colour, laser_image = acq.board, acq.stripe
    else:
        colour = rig.grab_frame(laser=False)
    raise_if_cancelled(cancel, "location")
    rig.runlog.image("locate/image", colour)
    cubes, diag = rig.run_logged(
        locate_in_images,
        colour,
        laser_image,
        calib,
        cfg,
        T_SB,
        calib.robot_base,
        prefix="locate",
        laser_color=rig.laser_color(),
        cancel=cancel,
        what="location",
    )
    result = LocateResult(cubes, diag, cfg.max_sigma_mm, colors=request.colors)
    result.shown = [cube_pixels(calib, T_SB, c) for c in cubes]
    result.picture = write_picture(
        rig.picture_path("locate", request.image),
        lambda: draw_cubes(colour, calib, T_SB, cubes, result.lines()),
    )
    return result


def locate_in_images(
    colour: np.ndarray,
    laser_image: np.ndarray | None,
    calib: SystemCalibration,
    cfg: SortConfig,
    T_SB: np.ndarray,
    robot_base: Mapping[str, Any] | None,
    log: RunLog = NullLog,
    prefix: str = "sorting",
    laser_color: str = "red",
) -> tuple[list[Cube], dict[str, Any]]:
    """The cubes in `colour` (laser off) with the laser-on image's stripe (of a `laser_color`
    laser) as height check; `robot_base` is the registration record (its board area is
    excluded)."""
    lp = None
    if laser_image is not None:
        px = laser_stripe_points(laser_image, color=laser_color)
        lp = pixels_to_plane(px, calib)
        log.points2d(f"{prefix}/laser_image/stripe", px, color=(255, 0, 0), radius=1)
    settings = locate_settings_for(cfg, calib, robot_base)
    cubes, diag = locate_cubes(colour, calib.model, calib.R_SC, T_SB, cfg.colors, settings, lp)
    p = calib.parameters()
    angles = np.radians([p["cam_roll_deg"], p["cam_pitch_deg"], p["cam_yaw_deg"]])
    size, floor_z = settings.cube_size_mm, settings.floor_z_B_mm
    rot_cov = rotation_covariance(calib.covariance)
    add_calibration_part(cubes, calib.R_SC, angles, T_SB, size, floor_z, rot_cov)
    log_cubes(log, prefix, cubes, diag)
    return cubes, diag


def locate_settings_for(
    cfg: SortConfig, calib: SystemCalibration, robot_base: Mapping[str, Any] | None
) -> LocateSettings:
    """Where cubes are looked for: `[sorting]`'s region (else between the target's walls),
    without the floor board's area."""
    settings = cfg.locate_settings(board_exclusion(robot_base))
    if settings.region_S_mm is None:
        settings = replace(settings, region_S_mm=default_region(calib.target))
    return settings


def board_exclusion(
    robot_base: Mapping[str, Any] | None,
) -> list[tuple[float, float, float, float]]:
    """The floor board's area in S (objects there are the board's squares), if known."""
    if not isinstance(robot_base, Mapping) or "board_extent_S_mm" not in robot_base:
        return []
    ext = robot_base["board_extent_S_mm"]
    return [tuple(float(v) for v in ext)]  # type: ignore[list-item]


def default_region(target: Mapping[str, Any]) -> tuple[float, float, float, float] | None:
    """Between the target's walls (from the calibration's target record), 20 mm inside them."""
    left = target.get("wall_left_x_mm")
    right = target.get("wall_right_x_mm")
    if left is None or right is None:
        sep = target.get("separation_mm")
        centre = target.get("center_mm", [0.0, 0.0])
        if sep is None:
            return None
        left, right = centre[0] - sep / 2.0, centre[0] + sep / 2.0
    y0, y1 = -1e9, 1e9
    if "length_mm" in target and "center_mm" in target:
        y0 = target["center_mm"][1] - target["length_mm"] / 2.0
        y1 = target["center_mm"][1] + target["length_mm"] / 2.0
    return (float(left) + 20.0, float(right) - 20.0, float(y0), float(y1))


def log_cubes(log: RunLog, prefix: str, cubes: Sequence[Cube], diag: Mapping[str, Any]) -> None:
    """Colour masks, blob outlines and cube centres of a location."""
    if not log.enabled:
        return
    masks = diag.get("masks", {})
    for name, m in masks.items():
        log.image(f"{prefix}/masks/{name}", m, bgr=False)
    strips = [c.outline_px for c in cubes if c.outline_px is not None]
    if strips:
        log.points2d(
            f"{prefix}/image/outlines", np.concatenate(strips), color=(255, 255, 0), radius=0.5
        )
    if cubes:
        log.points3d(f"{prefix}/cubes_S", np.array([c.center_S for c in cubes]), radius=20.0)
        log.points3d(f"{prefix}/cubes_B", np.array([c.center_B for c in cubes]), radius=20.0)
    log.text(f"{prefix}/cubes", json.dumps([to_wire(c.summary()) for c in cubes], indent=1))
