"""Intrinsic calibration: checkerboard images -> the camera's OCamCalib model and its record.

One use case for the CLI (`omnisort intrinsics calibrate`) and the service
(`calibrate what=intrinsics`), `run(rig, IntrinsicsRequest)`: read the images (every one
must be readable, or nothing is done), calibrate with the core, build the camera.json record
and the technician's report (PNG beside camera.json, and in the run log) once.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.intrinsics import IntrinsicResult, calibrate_images
from omnisort_hw.core.intrinsics_report import (
    LOW_COVERAGE,
    OUTER_BAND,
    ReportFigures,
    build_report,
    log_report,
)
from omnisort_hw.core.intrinsics_uncertainty import (
    cross_validate,
    model_uncertainty,
    projection_uncertainty,
    same_board_views,
    uncertainty_png,
    unique_images,
)
from omnisort_hw.core.overlays import write_png
from omnisort_hw.core.records import CrossValidation, ProjectionSigma, RejectedImage
from omnisort_hw.errors import InputError, MotionRefusedError
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.pipeline.replies import IntrinsicsReply
from omnisort_hw.pipeline.requests import IntrinsicsRequest
from omnisort_hw.pipeline.rig import Rig, raise_if_cancelled
from omnisort_hw.pipeline.verdict import Check, Verdict, graded
from omnisort_hw.runlog import NullLog, RunLog
from omnisort_hw.wire_records import from_wire, to_wire

IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})


@dataclass
class IntrinsicCalibration:
    """The core's result, the record camera.json stores with the model, and the report."""

    result: IntrinsicResult
    record: dict[str, Any]
    figures: ReportFigures
    picture: np.ndarray
    uncertainty_picture: np.ndarray | None = None

    def write_report(self, camera_json: str | Path) -> Path:
        """Write the report picture (and the projection uncertainty's map, `*_uncertainty.png`)
        beside `camera_json` (atomically); the report's path."""
        if self.uncertainty_picture is not None:
            write_png(uncertainty_png_path(Path(camera_json)), self.uncertainty_picture)
        return write_png(report_png_path(Path(camera_json)), self.picture)


def report_png_path(camera_json: Path) -> Path:
    """The report picture's place: beside camera.json, named after it."""
    return camera_json.with_name(camera_json.stem + "_report.png")


def uncertainty_png_path(camera_json: Path) -> Path:
    """The projection uncertainty map's place: beside camera.json, named after it."""
    return camera_json.with_name(camera_json.stem + "_uncertainty.png")


def board_record(board: BoardSpec) -> dict[str, Any]:
    """The board as camera.json and system.json's robot_base record it."""
    return {"inner_corners": [board.cols, board.rows], "square_mm": board.square_mm}


def image_files(folder: str | Path) -> list[Path]:
    """The image files of `folder`, sorted by name; InputError when there are none."""
    path = Path(folder)
    if path.is_file():
        raise InputError(f"{path}: is a file; give the folder of the checkerboard images")
    if not path.is_dir():
        raise InputError(f"{path}: no such folder")
    files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
    if not files:
        raise InputError(f"{path}: no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
    return files


def read_images(
    paths: Sequence[Path], cancel: threading.Event | None = None
) -> list[tuple[str, np.ndarray]]:
    """Read every image or fail naming the first unreadable one (nothing is written then)."""
    images = []
    for path in paths:
        if cancel is not None and cancel.is_set():
            raise MotionRefusedError("calibration cancelled")
        images.append((str(path), read_image(path)))
    return images


RIM_ANGLE_DEG = 80.0
"""Where the model is judged for the extrinsics: the walls and the laser line are seen out to
80-90 deg off the axis (one of the report's uncertainty angles)."""
ANGLE_GOAL_DEG = 0.03
"""The extrinsic calibration's goal for each angle (pipeline.extrinsics.ANGLE_STD_DEG's fail
threshold): a projection sigma of a quarter of it, in pixels, passes (its 2 sigma within half
the goal); beyond the whole goal the model fails there."""
CORNER_RMS_PX = (0.5, 1.0)
"""Corner RMS (px) that passes, and beyond which a calibration fails: twice what the renders
give (0.23 px, Unity's point-sampled faces; a real lens gives 0.08 px), and the pixel beyond
which corners were not found where they are."""


@dataclass
class IntrinsicsResult:
    """A calibration, the camera.json it was saved as and its report picture."""

    calibration: IntrinsicCalibration
    path: Path
    report: Path

    def reply(self) -> IntrinsicsReply:
        """The answer at every door (the service's reply, the CLI's `--json`)."""
        cal = self.calibration
        result, rec, figures = cal.result, cal.record, cal.figures
        return IntrinsicsReply(
            path=str(self.path),
            report=str(self.report),
            rms_px=result.rms_px,
            per_image_rms_px=rec["per_image_rms_px"],
            images_used=len(result.images_used),
            images_rejected=[from_wire(RejectedImage, r) for r in rec["images_rejected"]],
            corners_rejected=len(result.corners_rejected),
            corner_refinement=rec["corner_refinement"],
            std=rec["std"],
            poly_degree=result.degree,
            board=rec["board"],
            coverage=rec["coverage"],
            cross_validation=from_wire(CrossValidation, rec["cross_validation"]),
            projection_uncertainty=from_wire(ProjectionSigma, rec["projection_uncertainty"]),
            repeated_views=rec["repeated_views"],
            created=rec["created"],
            outer_band_covered=figures.outer_coverage,
            center_uv=list(result.model.center_uv),
            model=result.model.to_dict(),
            field_of_view_deg={
                "image_circle": figures.circle_field_deg,
                "corners_seen": figures.corners_field_deg,
            },
            verdict=self.verdict(),
            uncertainty_png=str(uncertainty_png_path(self.path))
            if cal.uncertainty_picture is not None
            else None,
            repeated_views_warning=rec.get("repeated_views_warning"),
            images_folder=rec.get("images_folder"),
        )

    def rim_sigma(self) -> tuple[float, float] | None:
        """(projection sigma, the extrinsic goal in pixels) at RIM_ANGLE_DEG off the axis, or
        None when the uncertainty was not estimated there. The goal: ANGLE_GOAL_DEG of
        direction, in the model's own pixels per degree there."""
        unc = from_wire(ProjectionSigma, self.calibration.record["projection_uncertainty"])
        sigma = unc.median_px_at_angle_deg.get(f"{RIM_ANGLE_DEG:g}")
        if sigma is None:
            return None
        model = self.calibration.result.model
        a = np.radians([RIM_ANGLE_DEG, RIM_ANGLE_DEG + 0.1])
        rays = np.stack([np.sin(a), np.zeros(2), np.cos(a)], axis=1)
        px = model.ray_to_pixel(rays)
        px_per_deg = float(np.linalg.norm(px[1] - px[0])) / 0.1
        return float(sigma), ANGLE_GOAL_DEG * px_per_deg

    def verdict(self) -> Verdict:
        """The corners' RMS against what a corner detector gives (CORNER_RMS_PX), and the model
        at the image circle's rim, where the targets and the laser line are: its projection
        sigma against the extrinsic goal there, and the rim's coverage by corners (few corners
        at the rim are a warning only when the sigma there is not small)."""
        figures = self.calibration.figures
        coverage = figures.outer_coverage
        rim = self.rim_sigma()
        checks = []
        rim_ok = False
        if rim is not None:
            sigma, goal_px = rim
            rim_check = graded(
                f"projection sigma at {RIM_ANGLE_DEG:g} deg off axis",
                sigma,
                "px",
                goal_px / 4.0,
                goal_px,
                advice="add views with the board near the rim of the image circle",
            )
            rim_ok = rim_check.level == "pass"
            checks.append(rim_check)
        covered = Check(
            f"outer {OUTER_BAND:.0%} of the image circle covered",
            "pass" if coverage >= LOW_COVERAGE or rim_ok else "warn",
            f"{coverage:.0%}",
            f">= {LOW_COVERAGE:.0%}, or a small sigma at the rim",
            ""
            if coverage >= LOW_COVERAGE or rim_ok
            else "add views with the board near the rim, where the targets and the laser "
            "line are (the report's uncertainty map shows where the model is known)",
        )
        rms = graded(
            "corner RMS",
            self.calibration.result.rms_px,
            "px",
            *CORNER_RMS_PX,
            advice="look at the report's residuals: a blurred or moved view, a wrong board size",
        )
        return Verdict("intrinsics", (rms, *checks, covered))


def run(
    rig: Rig,
    request: IntrinsicsRequest,
    cancel: threading.Event | None = None,
    on_detected: Callable[[str], None] | None = None,
) -> IntrinsicsResult:
    """Calibrate from the request's images (every one readable, or nothing is done), save the
    model as the rig's camera.json and the report beside it. `on_detected` (a progress bar)
    is called per image where the rig calibrates in its own process."""
    asked = request.calibrate
    board = asked.board_spec()
    rig.runlog.event(
        "calibration/intrinsics", f"{len(request.images)} images, board {board.cols}x{board.rows}"
    )
    extra = {} if on_detected is None else {"on_detected": on_detected}
    cal = rig.run_logged(
        calibrate_files,
        list(request.images),
        board,
        asked.degree,
        asked.refinement or "auto",
        cancel=cancel,
        what="calibration",
        **extra,
    )
    raise_if_cancelled(cancel, "calibration")
    if asked.folder is not None:
        cal.record["images_folder"] = asked.folder
    saved = rig.save_camera(cal.result.model, cal.record)
    return IntrinsicsResult(cal, saved, cal.write_report(saved))


def calibrate_files(
    paths: Sequence[Path],
    board: BoardSpec,
    degree: int | None = None,
    refinement: str = "auto",
    log: RunLog = NullLog,
    on_detected: Callable[[str], None] | None = None,
) -> IntrinsicCalibration:
    """Read the images and calibrate (what the service's compute worker runs)."""
    return calibrate_intrinsics(
        read_images(paths),
        board,
        degree=degree,
        on_detected=on_detected,
        log=log,
        refinement=refinement,
    )


def calibrate_intrinsics(
    images: list[tuple[str, np.ndarray]],
    board: BoardSpec,
    degree: int | None = None,
    on_detected: Callable[[str], None] | None = None,
    log: RunLog = NullLog,
    refinement: str = "auto",
) -> IntrinsicCalibration:
    """Calibrate from (name, image) pairs; the record holds the board, the outer-band coverage
    and the creation time; the report goes to the run log. A view given twice (the same
    pixels, or a board that did not move) is counted once, with a warning in the record; the
    record holds the cross-validated error beside the in-sample RMS and the projection
    uncertainty, and the model carries the intrinsics' covariance."""
    images, repeats = unique_images(images)
    result = calibrate_images(
        images, board, degree=degree, on_detected=on_detected, log=log, refinement=refinement
    )
    still = same_board_views(result)
    if still:
        again = {r["file"] for r in still}
        images = [im for im in images if im[0] not in again]
        result = calibrate_images(
            images, board, degree=degree, on_detected=on_detected, log=log, refinement=refinement
        )
        repeats += still
    unc = projection_uncertainty(result)
    result.model = replace(result.model, uncertainty=model_uncertainty(result))
    figures, picture = build_report(result, images)
    log_report(log, figures, picture)
    record = {
        **result.record(),
        "board": board_record(board),
        "coverage": {
            "outer_band_fraction": OUTER_BAND,
            "outer_band_covered": figures.outer_coverage,
            "image_circle_radius_px": figures.circle_radius_px,
            "warning": figures.warning,
        },
        "cross_validation": to_wire(cross_validate(result, board.object_points())),
        "projection_uncertainty": to_wire(unc.record()),
        "repeated_views": repeats,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    if repeats:
        record["repeated_views_warning"] = (
            f"{len(repeats)} view(s) repeat another one and were counted once: "
            + ", ".join(f"{Path(r['file']).name} = {Path(r['same_as']).name}" for r in repeats)
        )
    log.scalar("calibration/intrinsics/rms_px", result.rms_px)
    log.text(
        "calibration/intrinsics/parameters",
        json.dumps({"model": result.model.to_dict(), "std": result.std}, indent=1, default=str),
    )
    map_png = uncertainty_png(unc, within_deg=figures.circle_field_deg / 2.0)
    return IntrinsicCalibration(result, record, figures, picture, map_png)
