"""Table 3 with measurement captures: the same configurations and seeds as the rendered
datasets (`sim_backend.dataset`), but each target is seen by the simulated camera in its
"real camera" mode and measured the way the cell measures: N laser-on and N laser-off frames
(uncompressed, stripe exposure), the stripe found in their difference, and N laser-off board
frames for edges and markers (`pipeline.measurement_capture`). Errors against truth as in
`evaluation.table3` (same rows, same summary), plus the capture time.

`--frames 1` without differencing is the rendered degraded dataset (`evaluate_dataset`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.errors import OmnisortError
from omnisort_hw.evaluation.table3 import (
    RUNS,
    TARGET_OF,
    MethodStats,
    mapping_errors,
)
from omnisort_hw.pipeline.extrinsics import calibrate_system
from omnisort_hw.pipeline.image_files import read_image
from omnisort_hw.pipeline.measurement_capture import MeasurementCapture, capture_measurement
from sim_backend.dataset import TABLE3_SCENES, table3_bases, table3_configs
from sim_backend.devices import SimCamera, SimCell, SimLaserSwitch
from sim_backend.scene import Scene

EVAL_GRAB_TIMEOUT_S = 900.0  # a first 1920 px render on a loaded machine takes minutes


def _measure(
    scene: Scene, seed: int, settings: CaptureSettings
) -> tuple[MeasurementCapture, dict[str, Any], np.ndarray]:
    """The capture, the truth and the clean image, all from one render of the scene."""
    cell = SimCell(scene, seed)
    try:
        with (
            SimCamera(cell, degraded=True, grab_timeout_s=EVAL_GRAB_TIMEOUT_S) as cam,
            SimLaserSwitch(cell) as laser,
        ):
            laser.on()
            cam.grab(with_truth=True)
            truth = cam.last_truth
            assert truth is not None
            return capture_measurement(cam, laser, settings), truth, cam.clean_image()
    finally:
        cell.close()


def _calibrate(
    method: str,
    scene: str,
    image: np.ndarray,
    truth: dict[str, Any],
    tone: ToneCurve,
    stripe_px: np.ndarray | None,
) -> SystemCalibration:
    """One method on one target's image (a capture's board image and stripe points, or the
    clean render with the stripe found in it)."""
    model = OcamModel.from_dict(truth["camera"])
    target = TARGET_OF[scene]
    if target == "checkerboards":
        boards = truth.get("checkerboards") or []
        return calibrate_system(
            image,
            model,
            target,
            method,
            board=tuple(boards[0]["inner_corners"]) if boards else (9, 6),
            square_mm=float(boards[0]["square_mm"]) if boards else 97.0,
            tone=tone,
            stripe_px=stripe_px,
        )
    return calibrate_system(
        image,
        model,
        target,
        method,
        separation_mm=float(truth["target"]["separation_mm"]),
        tone=tone,
        stripe_px=stripe_px,
    )


def _summary(stats: dict[str, MethodStats], mapping: list[np.ndarray]) -> dict[str, Any]:
    rel = np.concatenate(mapping) if mapping else np.zeros(0)
    return {
        "methods": {m: st.summary() for m, st in stats.items()},
        "mapping": {
            "max_rel_error": float(rel.max()) if rel.size else None,
            "mean_rel_error": float(rel.mean()) if rel.size else None,
            "samples": int(rel.size),
        },
    }


def _fail(stats: dict[str, MethodStats], name: str, message: str) -> None:
    """Every row of the table that calibrates from target `name` failed with `message`."""
    for row, (_, scene) in RUNS.items():
        if scene == name:
            stats[row].failures.append(message)


def _count(
    stats: dict[str, MethodStats],
    mapping: list[np.ndarray],
    name: str,
    image: np.ndarray,
    truth: dict[str, Any],
    tone: ToneCurve,
    stripe_px: np.ndarray | None,
    folder: str,
) -> None:
    """Every row of the table that calibrates from target `name`, on one image."""
    for row, (method, scene) in RUNS.items():
        if scene != name:
            continue
        t0 = time.perf_counter()
        try:
            calib = _calibrate(method, scene, image, truth, tone, stripe_px)
        except OmnisortError as exc:
            stats[row].failures.append(f"{folder}: {exc}")
            continue
        stats[row].add(calib, truth, time.perf_counter() - t0)
        if row == "joint":
            mapping.append(mapping_errors(calib, SystemCalibration.from_json(truth)))


@dataclass
class _Tally:
    """What both evaluations accumulate: each row's errors on the captures and on the clean
    renders they were exposed from, the joint rows' mapping errors, and the capture records."""

    stats: dict[str, MethodStats] = field(default_factory=lambda: {m: MethodStats() for m in RUNS})
    clean: dict[str, MethodStats] = field(default_factory=lambda: {m: MethodStats() for m in RUNS})
    mapping: list[np.ndarray] = field(default_factory=list)
    clean_mapping: list[np.ndarray] = field(default_factory=list)
    capture_s: list[float] = field(default_factory=list)
    retries: int = 0

    def add(
        self,
        name: str,
        folder: str,
        truth: dict[str, Any],
        record: dict[str, Any],
        board: tuple[np.ndarray, ToneCurve, np.ndarray | None],
        clean: tuple[np.ndarray, ToneCurve],
    ) -> None:
        """One target's capture (`record`; board image, its tone curve, the stripe pixels) and
        the clean render it was exposed from (image, nominal tone curve)."""
        self.capture_s.append(float(record["capture_s"]))
        self.retries += int(record["retries"])
        image, tone, stripe_px = board
        _count(self.stats, self.mapping, name, image, truth, tone, stripe_px, folder)
        _count(self.clean, self.clean_mapping, name, clean[0], truth, clean[1], None, folder)

    def summary(self) -> dict[str, Any]:
        return {
            **_summary(self.stats, self.mapping),
            "capture": {
                "mean_capture_s": float(np.mean(self.capture_s)) if self.capture_s else None,
                "re_exposures": self.retries,
            },
            "clean": _summary(self.clean, self.clean_mapping),
        }


def evaluate_captures(
    n: int,
    seed: int,
    frames: int,
    width: int | None = None,
    progress: bool = True,
    partial: Path | None = None,
    keep: Path | None = None,
    only: Sequence[int] | None = None,
    effects: bool = False,
) -> dict[str, Any]:
    """Every configuration measured with captures of `frames` on/off pairs; the summary of
    `evaluate_dataset` plus the capture times, and under `clean` the same summary on the clean
    renders of the same configurations (the render the captures are exposed from: the bytes
    of the clean rendered dataset). `partial`: a JSON file rewritten after every
    configuration (for long runs). `keep`: a folder where each target's capture (board image,
    laser-light image, measured response) and clean image are kept, so a change to the
    extraction or the solvers is measured again by `evaluate_kept` without exposing again.
    `only`: the indices of the configurations to measure, in that order (shards of a long
    run, kept in one folder and measured together by `evaluate_kept`). `effects`: every frame
    through the colour camera's effects as well (crosstalk, chromatic aberration, bloom, Bayer
    demosaicing: `scene.with_camera_effects`); the clean reference stays the clean render."""
    from tqdm import tqdm

    bases = table3_bases(width, "srgb", effects=effects)  # the rendered dataset's scenes
    t_start = time.perf_counter()
    settings = CaptureSettings(frames=frames)
    tone = ToneCurve.srgb()  # the simulated camera's nominal curve; a capture measures its own
    tally = _Tally()
    configs = table3_configs(n, seed)
    if only is not None:
        configs = [configs[i] for i in only]
    result: dict[str, Any] = {}
    bar = tqdm(
        total=len(configs) * len(bases), desc="captures", unit="target", disable=not progress
    )
    for done, cfg in enumerate(configs, 1):
        for k, (name, base) in enumerate(bases):
            image_seed = seed * 100003 + cfg.index * 7 + k  # as the rendered dataset
            try:
                cap, truth, clean_image = _measure(cfg.apply(base), image_seed, settings)
            except (OmnisortError, Exception) as exc:  # a device error is a failure here too
                if not isinstance(exc, OmnisortError) and not hasattr(exc, "code"):
                    raise
                _fail(tally.stats, name, f"{cfg.folder}/{name}: {exc}")
                if keep is not None:
                    (keep / cfg.folder).mkdir(parents=True, exist_ok=True)
                    (keep / cfg.folder / f"{name}.failed.txt").write_text(f"{exc}")
                bar.update(1)
                continue
            if keep is not None:
                _keep(keep / cfg.folder, name, cap, truth, clean_image)
            assert cap.board_image is not None
            board = (cap.board_image, cap.tone or tone, cap.stripe_px)
            tally.add(name, cfg.folder, truth, cap.record, board, (clean_image, tone))
            bar.update(1)
        result = {
            "n": n,
            "done": done,
            "configs": [c.folder for c in configs[:done]],
            "seed": seed,
            "degraded": True,
            "effects": effects,
            "frames": frames,
            "differencing": True,
            "width": width or 1920,
            **tally.summary(),
            "wall_s": round(time.perf_counter() - t_start, 1),
        }
        if partial is not None:
            partial.parent.mkdir(parents=True, exist_ok=True)
            partial.write_text(json.dumps(result))
    bar.close()
    return result


def _keep(
    folder: Path, name: str, cap: MeasurementCapture, truth: dict[str, Any], clean: np.ndarray
) -> None:
    assert cap.board_image is not None
    folder.mkdir(parents=True, exist_ok=True)
    for kind, image in (("board", cap.board_image), ("stripe", cap.stripe_image), ("clean", clean)):
        if not cv2.imwrite(str(folder / f"{name}.{kind}.png"), image):
            raise OSError(f"{folder / name}.{kind}.png: could not be written")
    record = {
        "truth": truth,
        "record": cap.record,
        "tone": cap.tone.light.tolist() if cap.tone else None,
    }
    (folder / f"{name}.capture.json").write_text(json.dumps(record))


def evaluate_kept(
    keep: Path, configs: list[str], frames: int, progress: bool = True
) -> dict[str, Any]:
    """`evaluate_captures`'s result again from the captures it kept in `keep` (the stripe
    found again in each laser-light image): for changes after the exposure."""
    from tqdm import tqdm

    from omnisort_hw.core.laser_stripe import laser_stripe_points

    tone = ToneCurve.srgb()
    tally = _Tally()
    bar = tqdm(total=len(configs) * len(TABLE3_SCENES), desc="kept captures", disable=not progress)
    for folder in configs:
        for name in TABLE3_SCENES:
            base = keep / folder / name
            failed = Path(f"{base}.failed.txt")
            if failed.is_file():
                _fail(tally.stats, name, f"{folder}/{name}: {failed.read_text()}")
                bar.update(1)
                continue
            kept = json.loads(Path(f"{base}.capture.json").read_text())
            images = {k: read_image(f"{base}.{k}.png") for k in ("board", "stripe", "clean")}
            truth, record = kept["truth"], kept["record"]
            board_tone = ToneCurve("measured", np.asarray(kept["tone"])) if kept["tone"] else tone
            stripe_px = laser_stripe_points(images["stripe"], light_only=True)
            board = (images["board"], board_tone, stripe_px)
            tally.add(name, folder, truth, record, board, (images["clean"], tone))
            bar.update(1)
    bar.close()
    return {
        "n": len(configs),
        "done": len(configs),
        "configs": configs,
        "frames": frames,
        "differencing": True,
        **tally.summary(),
    }
