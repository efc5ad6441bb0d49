"""Extrinsic calibration: one target image -> features -> camera rotation and laser plane.

One use case for the CLI (`omnisort extrinsics calibrate`) and the service (`calibrate`),
`run(rig, CalibrateRequest)`; the evaluation calls `run_extrinsics` on its renders.

Picks the extractor for the target and the method (the best one for the target by default),
checks the image against the camera model, and logs what it saw and produced.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.config.target import separation_problem
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.choices import METHODS_FOR, TARGETS
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.features import BoardsFeatures, TargetFeatures
from omnisort_hw.core.overlays import draw_extrinsics, overlay_path, write_picture
from omnisort_hw.core.radiometry import SRGB, ToneCurve
from omnisort_hw.core.records import PictureReply
from omnisort_hw.core.target_layout import TargetLayout
from omnisort_hw.errors import InputError, NoLaserLineError
from omnisort_hw.pipeline.cell_acquisition import acquire
from omnisort_hw.pipeline.image_files import check_image_size
from omnisort_hw.pipeline.replies import ExtrinsicsReply
from omnisort_hw.pipeline.requests import CalibrateRequest
from omnisort_hw.pipeline.rig import Rig, raise_if_cancelled
from omnisort_hw.pipeline.scale_check import ScaleCheck, check_scale
from omnisort_hw.pipeline.verdict import Check, Verdict, graded
from omnisort_hw.runlog import NullLog, RunLog


def check_separation_mm(value: float | None, field: str) -> float:
    """`value` as a measured wall distance in mm, or an InputError naming `field`."""
    if value is None:
        raise InputError(
            f"{field}: required for the wall targets: the measured inner distance between "
            "the walls, in mm"
        )
    problem = separation_problem(value)
    if problem:
        raise InputError(f"{field}: {problem}")
    return float(value)


def resolve_target(
    target: str | None,
    separation_mm: float | None,
    default_kind: str | None,
    default_separation_mm: float | None,
    field: str,
) -> tuple[str, float | None]:
    """The target kind and, for the wall targets, its measured separation: the request's, else
    the cell file's `[target]` defaults. The separation is required and range-checked for a
    wall target and refused for boards; `field` names it in the errors."""
    kind = target or default_kind
    if kind is None:
        raise InputError(f"target: one of {', '.join(TARGETS)} is needed (or [target] kind)")
    if kind == "checkerboards":
        if separation_mm is not None:
            raise InputError(f"{field} is for the wall targets; boards take board and square")
        return kind, None
    value = separation_mm if separation_mm is not None else default_separation_mm
    return kind, check_separation_mm(value, field)


@dataclass
class ExtrinsicsRun:
    """A calibration and the features it was computed from (what its picture shows)."""

    calib: SystemCalibration
    features: TargetFeatures | BoardsFeatures

    def overlay(self, image: np.ndarray, title: str = "") -> np.ndarray:
        """The calibration image with the features and the fitted model reprojected."""
        return draw_extrinsics(image, self.features, self.calib, title)


def calibrate_system(*args: Any, **kwargs: Any) -> SystemCalibration:
    """`run_extrinsics` (same arguments) for callers that need only the calibration."""
    return run_extrinsics(*args, **kwargs).calib


def run_extrinsics(
    image: np.ndarray,
    model: OcamModel,
    target: str,
    method: str | None = None,
    separation_mm: float | None = None,
    board: tuple[int, int] = (9, 6),
    square_mm: float = 97.0,
    source: str = "image",
    log: RunLog = NullLog,
    tone: ToneCurve = SRGB,
    stripe_px: np.ndarray | None = None,
    layout: TargetLayout | None = None,
    laser_color: str = "red",
) -> ExtrinsicsRun:
    """Extract the target's features from one image and run the chosen method on them;
    `tone` is the camera's tone curve (sRGB unless the camera is configured otherwise);
    `stripe_px` the laser points of a measurement capture (else found in the image); `layout`
    the target as measured (`config.target.load_target_description`; its separation is then
    the one used), else the symmetric paper target; `laser_color` the laser's. With the
    log on, the overlay picture (`ExtrinsicsRun.overlay`) goes to it as well."""
    if stripe_px is None:  # the image's stripe, of the laser's colour
        from omnisort_hw.core.laser_stripe import laser_stripe_points_stats

        stripe_px, found = laser_stripe_points_stats(image, color=laser_color)
        if found.presence is not None and not found.presence.present:
            raise NoLaserLineError(
                f"{source}: {found.presence.reason()}: is the {laser_color} laser on, and does "
                "its line cross the target?"
            )
    from omnisort_hw.core.extrinsics.joint import calibrate_joint
    from omnisort_hw.core.extrinsics.method1 import calibrate_method1
    from omnisort_hw.core.extrinsics.method2 import calibrate_method2
    from omnisort_hw.core.extrinsics.paper import calibrate_paper
    from omnisort_hw.core.target_features import extract_board_features, extract_target_features

    if target not in TARGETS:
        raise InputError(f"--target must be one of {', '.join(TARGETS)}, got {target!r}")
    method = method or METHODS_FOR[target][0]
    if method not in METHODS_FOR[target]:
        raise InputError(
            f"--method {method} does not work with the {target} target "
            f"(use {' or '.join(METHODS_FOR[target])})"
        )
    if layout is not None and layout.kind != target:
        raise InputError(f"{layout.source}: describes a {layout.kind} target, not {target}")
    if target != "checkerboards" and layout is None:
        separation_mm = check_separation_mm(separation_mm, "separation_mm")
    check_image_size(image, model, source)
    log.image("extrinsics/image", image)
    if target == "checkerboards":
        boards = extract_board_features(image, model, board, square_mm, stripe_px)
        for name, b in boards.boards.items():
            log.points2d(f"extrinsics/image/{name}_corners", b.corners_px, color=(0, 200, 0))
            log.points2d(f"extrinsics/image/{name}_laser", b.laser_px, color=(255, 0, 0), radius=1)
        run = ExtrinsicsRun(calibrate_method2(boards, model), boards)
    else:
        features = extract_target_features(
            image, model, kind=target, tone=tone, stripe_px=stripe_px
        )
        for name, wall in features.walls.items():
            log.points2d(
                f"extrinsics/image/{name}_border", wall.border_px, color=(255, 255, 0), radius=1
            )
            log.points2d(
                f"extrinsics/image/{name}_laser", wall.laser_px, color=(255, 0, 0), radius=1
            )
            if wall.markers_px:
                log.points2d(
                    f"extrinsics/image/{name}_markers",
                    np.array(list(wall.markers_px.values())),
                    color=(0, 80, 255),
                    radius=5,
                    labels=list(wall.markers_px),
                )
        solver = {"joint": calibrate_joint, "paper": calibrate_paper, "method1": calibrate_method1}[
            method
        ]
        if layout is not None:
            separation_mm = layout.separation_mm
        wall_mm = check_separation_mm(separation_mm, "separation_mm")  # a float for the walls
        run = ExtrinsicsRun(solver(features, model, wall_mm, layout), features)
    _log_calibration(log, run.calib)
    if log.enabled:
        log.image("extrinsics/overlay", run.overlay(image, source))
    return run


def run(
    rig: Rig, request: CalibrateRequest, cancel: threading.Event | None = None
) -> ExtrinsicsResult:
    """Calibrate from the request's image, or from a measurement capture (its averaged board
    frames for the edges and markers, its on/off pairs for the stripe), with the rig's camera
    model and tone curve; the target and wall distance default to the rig's `[target]`. The
    result is saved as the rig's system.json with the picture of what was detected and fitted
    beside it."""
    kind, separation_default, field = rig.target_defaults()
    layout = None
    if request.target_file is not None:
        from omnisort_hw.config.target import load_target_description

        layout = load_target_description(request.target_file)
        kind, separation_default = kind or layout.kind, layout.separation_mm
        field = f"separation_mm of {request.target_file}"
    target, separation = resolve_target(
        request.target, request.separation_mm, kind, separation_default, field
    )
    board = request.board_spec()
    model = rig.camera_model()
    acq = acquire(rig, request.image, board=True)
    tone = acq.tone or rig.tone_curve()
    raise_if_cancelled(cancel, "calibration")
    fitted = rig.run_logged(
        run_extrinsics,
        acq.board,
        model,
        target,
        request.method,
        separation_mm=separation,
        board=board.size,
        square_mm=board.square_mm,
        source=acq.source,
        tone=tone,
        stripe_px=acq.stripe_px,
        layout=layout,
        laser_color=rig.laser_color(),
        cancel=cancel,
        what="calibration",
    )
    raise_if_cancelled(cancel, "calibration")
    scale: ScaleCheck | str = "a checkerboards target has its own scale"
    if target != "checkerboards":
        floor_z_B = float(getattr(rig.sort_config, "floor_z_B_mm", 0.0) or 0.0)
        scale = rig.run_logged(
            check_scale,
            acq.board,
            fitted.calib,
            rig.registration_config,
            floor_z_B,
            cancel=cancel,
            what="scale check",
        )
    saved = rig.save_system(system_payload(fitted.calib, acq.record))
    picture = write_picture(overlay_path(saved), lambda: fitted.overlay(acq.board, acq.source))
    return ExtrinsicsResult(fitted.calib, target, saved, picture, acq.record, tone, scale)


def system_payload(calib: SystemCalibration, image: dict[str, Any] | None) -> dict[str, Any]:
    """The system.json payload of a calibration made from the image `image` (its record)."""
    calib.image = image
    payload = calib.to_json()
    payload["elapsed_s"] = round(calib.elapsed_s, 4)
    return payload


@dataclass
class ExtrinsicsResult:
    """A calibration saved: the fit, the target, where it was saved, its picture, the image's
    record, the tone curve it was located with, and the separation against the image's own
    scale (or why that could not be checked)."""

    calib: SystemCalibration
    target: str
    path: Path
    picture: PictureReply
    image: dict[str, Any] | None
    tone: ToneCurve
    scale: ScaleCheck | str

    def verdict(self) -> Verdict:
        return calibration_verdict(self.calib, self.scale)

    def reply(self) -> ExtrinsicsReply:
        """The answer at every door (the service's reply, the CLI's `--json`)."""
        scale = self.scale
        checked = scale.record() if isinstance(scale, ScaleCheck) else {"not_checked": scale}
        return ExtrinsicsReply(
            path=str(self.path),
            method=self.calib.method,
            target=self.target,
            parameters=self.calib.parameters(),
            std=self.calib.std,
            residuals=self.calib.residuals,
            image=self.image,
            tone_curve=self.tone.name,
            scale_check=checked,
            verdict=self.verdict(),
            **vars(self.picture),
        )


ANGLE_STD_DEG = (0.015, 0.03)
"""An angle's 1-sigma (deg) that passes, and beyond which the calibration fails: the cell's
goal is each angle within 0.03 deg (commissioning), so 2 sigma within it passes."""
DISTANCE_STD_MM = (0.5, 1.0)
"""The laser distance's 1-sigma (mm) likewise, against its goal of 1 mm."""


def calibration_verdict(calib: SystemCalibration, scale: ScaleCheck | str | None = None) -> Verdict:
    """The fitted parameters' sigmas against the cell's goals (a method that gives none is a
    warning: the joint method does), and the separation against the floor board's scale when
    it could be checked."""
    std = calib.std or {}
    angles = [float(v) for k, v in std.items() if k.endswith("_deg") and v is not None]
    distance = std.get("laser_distance_mm")
    checks: list[Check]
    if not angles or distance is None:
        checks = [
            Check(
                "parameter sigmas",
                "warn",
                f"not estimated by {calib.method}",
                "the joint method gives them",
                "calibrate with the joint method to know how good the result is",
            )
        ]
    else:
        advice = "retake with the whole target in view, its borders and stripe sharp"
        checks = [
            graded("worst angle sigma", max(angles), "deg", *ANGLE_STD_DEG, advice=advice),
            graded("laser distance sigma", float(distance), "mm", *DISTANCE_STD_MM, advice=advice),
        ]
    if isinstance(scale, ScaleCheck):
        checks.append(scale.check())
    return Verdict("extrinsics", tuple(checks))


def _log_calibration(log: RunLog, calib: SystemCalibration) -> None:
    """Parameters, residuals, and the fitted laser plane drawn back into the image."""
    import json

    params = calib.parameters()
    for key, value in params.items():
        log.scalar(f"extrinsics/{calib.method}/{key}", value)
    log.text(
        f"extrinsics/{calib.method}/result",
        json.dumps(
            {"parameters": params, "std": calib.std, "residuals": calib.residuals}, indent=2
        ),
    )
    # The laser plane's circle at 1 m around the axis, projected: a check of the fit by eye.
    ang = np.linspace(-np.pi, np.pi, 361)
    n = calib.laser_normal
    ring = np.stack([1000 * np.cos(ang), 1000 * np.sin(ang), np.zeros_like(ang)], axis=1)
    ring[:, 2] = -calib.laser_distance_mm - (ring[:, 0] * n[0] + ring[:, 1] * n[1]) / n[2]
    px = calib.model.ray_to_pixel(ring @ calib.R_SC)
    log.lines2d(f"extrinsics/image/{calib.method}_laser_plane_1m", [px], color=(255, 128, 0))
