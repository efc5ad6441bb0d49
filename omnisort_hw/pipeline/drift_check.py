"""The drift check: one fresh capture against the stored calibration (use case,
`run(rig, CheckRequest)`).

Shared by `omnisort check [IMAGE]`, the service's `check` command, its periodic watchdog and
the check before each `sort`. The reference image is the laser-off capture the robot was
registered with (saved beside system.json as `drift_reference.png` with the key of the
calibration it belongs to); without it (e.g. a system.json registered elsewhere) the board's
corners alone give the rotation, less precisely. See `core.drift` and docs/drift.md.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from omnisort_hw import fileio
from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.config.watchdog import WatchdogConfig
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.drift import (
    BoardCheck,
    DriftDecision,
    RotationEstimate,
    decide,
    estimate_rotation,
    measure_board,
)
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.errors import FeatureNotFoundError, OmnisortError
from omnisort_hw.pipeline.cell_acquisition import frame
from omnisort_hw.pipeline.replies import DriftReply
from omnisort_hw.pipeline.requests import CheckRequest
from omnisort_hw.pipeline.verdict import Check, Verdict
from omnisort_hw.runlog import NullLog, RunLog

REFERENCE_NAME = "drift_reference.png"
REFERENCE_META = "drift_reference.json"
# Bias of refined board corners against the calibration's prediction (px), what the
# board-only fallback cannot resolve (docs/drift.md).
BOARD_BIAS_PX = 0.3


def calibration_key(system_payload: Mapping[str, object]) -> str:
    """What a drift result belongs to: the camera rotation, the model and the robot base."""
    keys = ("camera", "camera_rotation", "robot_base")
    body = {k: system_payload.get(k) for k in keys}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]


DRIFT_STATE_NAME = "drift.json"


def load_drift_state(state_dir: str | Path) -> dict[str, Any]:
    """The drift watchdog's state in `state_dir` (`{}` when there is none or it is unreadable:
    the watchdog then starts afresh)."""
    try:
        data = json.loads((Path(state_dir) / DRIFT_STATE_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def drift_refusal(state: Mapping[str, object], key: str | None) -> str | None:
    """Why motion is refused by the drift state `state` for the calibration `key`: a drift of
    that calibration that no operator acknowledged (a new calibration clears it by itself)."""
    drift = state.get("drift_detected")
    if not isinstance(drift, Mapping) or state.get("acknowledged") or key is None:
        return None
    if drift.get("calibration_key") != key:
        return None
    return (
        f"calibration drift: the camera turned {drift['angle_deg']:.3f} deg since the "
        f"calibration (threshold {drift['threshold_deg']:.3f} deg, checked "
        f"{drift['checked_at']}); recalibrate (calibrate what=extrinsics, register_robot) or "
        "send acknowledge_drift"
    )


def save_reference(state_dir: Path, image: np.ndarray, key: str) -> Path:
    """Keep `image` (the registration's capture) as the drift reference of calibration `key`."""
    ok, buf = cv2.imencode(".png", np.asarray(image))
    if not ok:
        raise OmnisortError("drift reference: PNG encoding failed")
    path = fileio.atomic_write_bytes(Path(state_dir) / REFERENCE_NAME, buf.tobytes(), False)
    meta = {"key": key, "saved": datetime.now(UTC).isoformat(timespec="seconds")}
    fileio.atomic_write_json(Path(state_dir) / REFERENCE_META, meta, keep_history=False)
    return path


def load_reference(state_dir: Path, key: str) -> np.ndarray | None:
    """The reference image of calibration `key`, or None (missing, unreadable, another key)."""
    try:
        meta = json.loads((Path(state_dir) / REFERENCE_META).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(meta, dict) or meta.get("key") != key:
        return None
    img = cv2.imread(str(Path(state_dir) / REFERENCE_NAME), cv2.IMREAD_COLOR)
    return img


@dataclass
class DriftResult:
    """One check: the decision, the board against its prediction, and when."""

    decision: DriftDecision
    board: BoardCheck | None
    key: str
    source: str
    checked_at: str = field(default_factory=lambda: datetime.now(UTC).isoformat(timespec="seconds"))
    board_problem: str | None = None
    frame: np.ndarray | None = field(default=None, repr=False)  # the image checked

    def reply(self) -> DriftReply:
        """The answer at every door (the service's reply, the CLI's `--json`)."""
        return self.summary()

    @property
    def drift(self) -> bool:
        return self.decision.drift

    def summary(self) -> DriftReply:
        return DriftReply(
            **vars(self.decision.summary()),
            checked_at=self.checked_at,
            image=self.source,
            calibration_key=self.key,
            board=self.board.summary() if self.board is not None else None,
            verdict=self.verdict(),
            board_problem=self.board_problem or None,
        )

    def verdict(self) -> Verdict:
        """The turn against the decision's own threshold (its false-alarm rate and the
        estimate's sigma): beyond it motion is refused until a recalibration or an
        acknowledgement."""
        d = self.decision
        turned = Check(
            "camera turned since the registration",
            "fail" if d.drift else "pass",
            f"{d.angle_deg:.4f} deg",
            f"drift above {d.threshold_deg:.4f} deg",
            "motion is refused: register the robot again (or recalibrate), or acknowledge "
            "the drift if the cell was checked by hand"
            if d.drift
            else "",
        )
        return Verdict("drift check", (turned,))


def registration_for(
    system_payload: Mapping[str, object], configured: RegistrationConfig | None
) -> RegistrationConfig | None:
    """The board a drift check compares: the cell file's `[registration]`, else the one
    system.json's `robot_base` was registered with (its board and offset are recorded), else
    None (the image check alone)."""
    if configured is not None:
        return configured
    record = system_payload.get("robot_base")
    if not isinstance(record, Mapping):
        return None
    board, offset = record.get("board"), record.get("offset")
    if not isinstance(board, Mapping) or not isinstance(offset, list) or len(offset) != 6:
        return None
    try:
        cols, rows = board["inner_corners"]
        spec = BoardSpec(int(cols), int(rows), float(board["square_mm"]))
        pose = tuple(float(v) for v in offset)
    except (KeyError, TypeError, ValueError):
        return None
    return RegistrationConfig(spec, pose)  # type: ignore[arg-type]


class CheckRig(Protocol):
    """What the drift check needs of a rig: the system calibration with where it came from, a
    laser-off frame, the reference image of a calibration, the `[registration]` and
    `[watchdog]` settings, and the run log."""

    @property
    def runlog(self) -> RunLog: ...

    @property
    def registration_config(self) -> RegistrationConfig | None: ...

    @property
    def watchdog_config(self) -> WatchdogConfig: ...

    def system_record(self) -> tuple[dict[str, Any], str]:
        """system.json's payload (its checksum verified) and its path."""
        ...

    def grab_frame(self, laser: bool) -> np.ndarray: ...

    def drift_reference(self, key: str) -> np.ndarray | None:
        """The laser-off image the calibration `key` was registered with, if kept."""
        ...


def run(rig: CheckRig, request: CheckRequest) -> DriftResult:
    """The request's image (or a laser-off capture) against the rig's calibration, its
    reference image and its floor board."""
    payload, where = rig.system_record()
    calib = SystemCalibration.from_json(payload, source=where)
    image = frame(rig, request.image, laser=False)
    result = check_drift(
        image,
        calib,
        payload,
        registration_for(payload, rig.registration_config),
        rig.drift_reference(calibration_key(payload)),
        rig.watchdog_config,
        request.image or "capture",
        rig.runlog,
    )
    result.frame = image
    return result


def check_drift(
    image: np.ndarray,
    calib: SystemCalibration,
    system_payload: Mapping[str, object],
    registration: RegistrationConfig | None,
    reference: np.ndarray | None,
    config: WatchdogConfig | None = None,
    source: str = "capture",
    log: RunLog = NullLog,
) -> DriftResult:
    """Compare a laser-off capture with the stored calibration (and its reference image)."""
    from omnisort_hw.pipeline.image_files import check_image_size

    check_image_size(image, calib.model, source)
    if reference is not None:
        check_image_size(reference, calib.model, f"{source}'s reference image")
    cfg = config or WatchdogConfig()
    est: RotationEstimate | None = None
    if reference is not None:
        est = estimate_rotation(reference, image, calib.model, calib.R_SC)
    board: BoardCheck | None = None
    problem = None
    base = system_payload.get("robot_base")
    if registration is not None and isinstance(base, Mapping) and "matrix" in base:
        T_SB = np.asarray(base["matrix"], float)
        board = measure_board(
            image,
            calib.model,
            calib.R_SC,
            T_SB,
            registration.T_B_board,
            registration.board,
            None if est is None else est.rotvec_S,
        )
        if board.n_visible < 4:
            problem = f"only {board.n_visible} board corners visible"
    else:
        problem = "no registered robot base or no [registration]: the board is not checked"
    if est is None:
        if board is None or board.rotation is None:
            raise FeatureNotFoundError(
                "drift check: no reference image for this calibration and too few floor-board "
                f"corners visible ({problem or 'fewer than 6'}); register the robot again"
            )
        est = board.rotation
    min_angle = cfg.min_angle_deg
    if est.source == "board":
        # Corner positions carry a bias the residual scatter does not show (detector against
        # the calibration's own fit): never call less than that bias's angle drift.
        px0 = calib.model.ray_to_pixel(np.array([[0.0, 0.0, 1.0]]))
        tilt = np.radians(1.0)
        px1 = calib.model.ray_to_pixel(np.array([[np.sin(tilt), 0.0, np.cos(tilt)]]))
        density = float(np.linalg.norm(px1 - px0))
        min_angle = max(min_angle, BOARD_BIAS_PX / density)
    decision = decide(est, cfg.false_alarm_rate, min_angle)
    result = DriftResult(
        decision, board, calibration_key(system_payload), source, board_problem=problem
    )
    _log(log, image, result)
    return result


def _log(log: RunLog, image: np.ndarray, result: DriftResult) -> None:
    log.image("drift/image", image)
    b = result.board
    if b is not None and b.visible.any():
        log.points2d("drift/image/predicted", b.predicted_px, color=(255, 200, 0), radius=2)
        log.points2d("drift/image/measured", b.measured_px[b.visible], color=(0, 200, 0), radius=2)
    log.scalar("drift/angle_deg", result.decision.angle_deg)
    log.scalar("drift/threshold_deg", result.decision.threshold_deg)
    log.event(
        "drift/check",
        f"{'DRIFT' if result.drift else 'ok'}: {result.decision.angle_deg:.4f} deg "
        f"(threshold {result.decision.threshold_deg:.4f} deg, {result.decision.source})",
        level="WARN" if result.drift else "INFO",
    )
