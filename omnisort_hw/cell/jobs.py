"""The cell's long commands: calibrate (intrinsics, extrinsics), map, register_robot, locate
and sort, each a call into the use-case layer (`omnisort_hw.pipeline`) with the cell's
devices, calibration store, run log, compute worker and the cell file's typed record.

`CellJobs` is a part of `cell.Cell` (its base class), kept apart because these are the use
cases and the rest of the cell is devices, status and motion; it names the attributes of the
cell it uses. A command whose section is missing raises `NotAvailableError` naming it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from omnisort_hw.config.cell import CellConfig
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import InputError, MotionRefusedError, OmnisortError
from omnisort_hw.pipeline.calibration_store import CalibrationStore

if TYPE_CHECKING:
    from contextlib import AbstractContextManager
    from pathlib import Path

    from omnisort_hw.cell.compute_worker import ComputeWorker
    from omnisort_hw.cell.devices import Devices
    from omnisort_hw.cell.journal import JobJournal
    from omnisort_hw.cell.watchdog import DriftWatchdog
    from omnisort_hw.config.capture import CaptureSettings
    from omnisort_hw.config.sorting import RegistrationConfig
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.runlog import RunLog


class NotAvailableError(OmnisortError):
    """A command needs a component that is not in this build (the message names it)."""

    code = "not_available"


class CellJobs:
    """The use cases of `cell.Cell` (see the module doc)."""

    devices: Devices
    store: CalibrationStore
    config: CellConfig
    compute: ComputeWorker
    journal: JobJournal
    drift: DriftWatchdog
    sort_config: SortConfig | None
    registration_config: RegistrationConfig | None

    if TYPE_CHECKING:  # defined by `Cell`

        @property
        def runlog(self) -> RunLog: ...

        def grab(self, timeout_s: float | None = None) -> Any: ...

        def set_laser(self, on: bool) -> bool: ...

        # and what makes it a `pipeline.cell_acquisition.CaptureRig`
        capture_dir: Path

        @property
        def capture_settings(self) -> CaptureSettings: ...

        def measuring(self) -> AbstractContextManager[tuple[Any, Any]]: ...

        def prune_captures(self) -> None: ...

    # -- pipeline (use cases) --------------------------------------------------------------

    def calibrate_intrinsics(
        self,
        folder: str,
        board: str = "9x6",
        square_mm: float = 0.0,
        degree: int | None = None,
        cancel: threading.Event | None = None,
    ) -> dict[str, Any]:
        """Intrinsic calibration from the checkerboard images of `folder`, saved as camera.json.

        The images are taken to come from the camera attached now (its serial is stored).
        """
        from omnisort_hw.core.camera_io import camera_record
        from omnisort_hw.core.checkerboard import BoardSpec
        from omnisort_hw.pipeline.intrinsics import calibrate_folder, image_files

        try:
            spec = BoardSpec.parse(board, square_mm)
        except ValueError as exc:
            raise InputError(f"calibrate: board/square_mm: {exc}") from None
        files = image_files(folder)
        rl = self.runlog
        rl.event("calibration/intrinsics", f"{len(files)} images from {folder}, board {board}")
        cal = self.compute.call_logged(
            calibrate_folder, rl, files, spec, degree, cancel=cancel, what="calibration"
        )
        _raise_if_cancelled(cancel, "calibration")
        result, record = cal.result, {**cal.record, "images_folder": str(folder)}
        saved = self.store.save_camera(camera_record(result.model, **record))
        report = cal.write_report(saved)
        return {
            "path": str(saved),
            "rms_px": result.rms_px,
            "images_used": len(result.images_used),
            "images_rejected": record["images_rejected"],
            "corners_rejected": len(result.corners_rejected),
            "outer_band_covered": cal.figures.outer_coverage,
            "report": str(report),
            "center_uv": list(result.model.center_uv),
            "poly_degree": result.degree,
            "camera_serial": self.store.expected_serial,
        }

    def calibrate_extrinsics(
        self,
        image: str | None = None,
        target: str | None = None,
        method: str | None = None,
        separation_mm: float | None = None,
        board: str | None = None,
        square_mm: float | None = None,
        cancel: threading.Event | None = None,
    ) -> dict[str, Any]:
        """Camera rotation and laser plane from one image of the calibration target (a fresh
        capture with the laser on, or `image`), saved as system.json. The previous robot base
        pose is not carried over: it was registered with the previous camera rotation."""
        from omnisort_hw.core.checkerboard import BoardSpec
        from omnisort_hw.core.overlays import overlay_path, write_picture
        from omnisort_hw.pipeline.extrinsics import (
            calibration_result,
            resolve_target,
            run_extrinsics,
            system_payload,
        )

        defaults = self.config.target
        field = "separation_mm (or [target] separation_mm in the cell file)"
        target, separation = resolve_target(
            target, separation_mm, defaults.kind, defaults.separation_mm, field
        )
        try:
            board_size = BoardSpec.parse(board or "9x6", square_mm or 97.0).size
        except ValueError as exc:
            raise InputError(f"calibrate: board/square_mm: {exc}") from None
        model = self.store.camera_model()
        tone = self.camera_tone_curve()
        acq = self.measure(image)
        img, record, source, tone = acq.board, acq.record, acq.source, acq.tone or tone
        _raise_if_cancelled(cancel, "calibration")
        run = self.compute.call_logged(
            run_extrinsics,
            self.runlog,
            img,
            model,
            target,
            method,
            separation_mm=separation,
            board=board_size,
            square_mm=square_mm or 97.0,
            source=source,
            tone=tone,
            cancel=cancel,
            what="calibration",
            stripe_px=acq.stripe_px,
        )
        _raise_if_cancelled(cancel, "calibration")
        calib = run.calib
        saved = self.store.save_system(system_payload(calib, record))
        # and the picture of what was detected and fitted (about 11 ms)
        picture = write_picture(overlay_path(saved), lambda: run.overlay(img, source))
        return calibration_result(calib, target, saved, picture, record, tone)

    def camera_tone_curve(self) -> ToneCurve:
        """The camera's transfer curve, undone wherever edges are located in its images (the
        extrinsic target's borders and markers); sRGB when the cell has no camera, what 8-bit
        image files hold."""
        from omnisort_hw.core.radiometry import ToneCurve

        camera = self.devices.camera
        return ToneCurve.parse(camera.tone_curve if camera is not None else None)

    def system_calibration(self) -> SystemCalibration:
        """The verified system.json as the core's SystemCalibration."""
        rec = self.store.read("system")
        return SystemCalibration.from_json(rec.payload, source=str(rec.path))

    def map_scene(
        self,
        image: str | None = None,
        cancel: threading.Event | None = None,
        with_points: bool = False,
        picture: bool = False,
    ) -> dict[str, Any]:
        """Laser map: the stripe's pixels -> points on the laser plane (S, mm) -> segments.

        `with_points` adds the points themselves (S, mm, 0.1 mm) and their pixels; `picture`
        writes the map's picture as map_overlay.png beside system.json (one, overwritten)."""
        from omnisort_hw.core.overlays import write_picture
        from omnisort_hw.pipeline.laser_map import floor_plane_S, map_laser, map_overlay

        calib = self.system_calibration()
        acq = self.measure(image, board=False)
        _raise_if_cancelled(cancel, "mapping")
        floor = floor_plane_S(calib, self.sort_config)  # the floor's mirror images go
        light = acq.stripe_px is not None  # a capture's laser light: red-channel centres
        laser_map = map_laser(acq.stripe, calib, acq.source, self.runlog, floor, light_only=light)
        out = {"image": acq.record, **laser_map.summary(with_points)}
        if picture:
            path = self.store.path("system").with_name("map_overlay.png")
            out |= write_picture(
                path, lambda: map_overlay(acq.stripe, laser_map, calib, acq.source)
            )
        return out

    def measure(self, image: str | None, board: bool = True) -> Any:
        """The file `image`, or a measurement capture (`pipeline.cell_acquisition`)."""
        from omnisort_hw.pipeline.cell_acquisition import acquire

        return acquire(self, image, board)

    def _image(self, image: str | None, laser: bool) -> np.ndarray:
        """The file `image`, or a capture with the laser switched to `laser` (off after)."""
        from omnisort_hw.pipeline.image_files import read_image

        if image is not None:
            return read_image(image)
        if self.devices.laser is not None:
            self.set_laser(laser)
        try:
            return np.asarray(self.grab().image)
        finally:
            if laser and self.devices.laser is not None:
                self.set_laser(False)

    def _sorting(self, what: str) -> SortConfig:
        if self.sort_config is None:
            raise NotAvailableError(
                f"{what} needs a [sorting] section in the cell configuration (bins, obstacles, "
                "cube size, home pose; or from_scene = true)"
            )
        return self.sort_config

    def register_robot(
        self, image: str | None, cancel: threading.Event | None = None
    ) -> dict[str, Any]:
        """Robot base pose T_SB from the floor checkerboard in `image` (or a laser-off
        capture), saved as `robot_base` in the store's system.json."""
        from omnisort_hw.pipeline.registration import register_from_image, robot_base_record

        rc = self.registration_config
        if rc is None:
            raise NotAvailableError(
                "the robot registration needs a [registration] section in the cell "
                "configuration (board, square_mm, offset = [X, Y, Z, RX, RY, RZ] of the board in B)"
            )
        payload = dict(self.store.load_system())
        calib = SystemCalibration.from_json(payload, source=str(self.store.path("system")))
        img = self._image(image, laser=False)
        self.runlog.image("registration/image", img)
        reg = self.compute.call_logged(
            register_from_image, self.runlog, img, calib, rc, cancel=cancel
        )
        payload["robot_base"] = robot_base_record(reg, rc, image or "capture")
        path = self.store.save_system(payload)
        self.drift.save_reference(img)
        return {"robot_base": payload["robot_base"], "path": str(path)}

    def locate(
        self, image: str | None, colors: list[str] | None, cancel: threading.Event | None = None
    ) -> dict[str, Any]:
        """The cubes in `image` (or laser-off and laser-on captures), in S and B."""
        from omnisort_hw.pipeline.calibration_source import robot_base_T
        from omnisort_hw.pipeline.locate import locate_in_images

        cfg = self._sorting("the colour-blob location")
        calib = self.system_calibration()
        T_SB = robot_base_T(calib, str(self.store.path("system")), for_motion=False)
        with_laser = image is None and cfg.use_laser and self.devices.laser is not None
        acq = self.measure(image) if with_laser else None
        colour = acq.board if acq is not None else self._image(image, laser=False)
        laser_img = acq.stripe if acq is not None else None
        args = (colour, laser_img, calib, cfg, T_SB, calib.robot_base)  # located in the worker
        cubes, _ = self.compute.call_logged(locate_in_images, self.runlog, *args, cancel=cancel)
        found = [c.summary() for c in cubes if colors is None or c.color in colors]
        return {"cubes": found, "count": len(found)}

    def sort(
        self,
        max_objects: int | None,
        colors: list[str] | None,
        cancel: threading.Event,
        progress: Callable[[dict[str, Any]], None] | None = None,
    ) -> dict[str, Any]:
        """Locate, pick and place every object by colour until done, `max_objects` or cancel;
        gated by the calibration store."""
        from omnisort_hw.pipeline.calibration_source import StoreCalibration, robot_base_T
        from omnisort_hw.pipeline.gripper_load import resolve_before_sort
        from omnisort_hw.pipeline.sort import Sorter
        from omnisort_hw.pipeline.sort_capture import sort_capture_for

        cfg = self._sorting("the sorting pipeline")
        if self.devices.camera is None or self.devices.arm is None:
            raise MotionRefusedError("sort: the cell needs a camera and an arm")
        laser = _CellLaser(self) if self.devices.laser is not None else None
        sorter = Sorter(
            _CellCamera(self),  # type: ignore[arg-type]
            self.devices.arm,
            laser,  # type: ignore[arg-type]
            StoreCalibration(self.store),
            cfg,
            self.registration_config,
            log=self.runlog,
            cancel=cancel,
            progress=progress,
            on_pick=lambda phase, o: self.journal.pick_phase(phase, o.index, o.color, o.bin),
            compute=self.compute,
            acquire=sort_capture_for(self),
        )
        sorter.calibration.check_motion_allowed()
        self.drift.before_sort()
        T_SB = robot_base_T(sorter.calibration.system())
        held = resolve_before_sort(sorter, self.journal, T_SB)
        report = sorter.run(max_objects, colors)
        if held is not None:
            report.outcomes.insert(0, held)
        return report.to_dict()


class _CellCamera:
    """The cell's camera through the cell (its lock and its run log)."""

    def __init__(self, cell: CellJobs) -> None:
        self.cell = cell

    def grab(self, timeout_s: float | None = None) -> Any:
        return self.cell.grab(timeout_s)


class _CellLaser:
    """The cell's laser switch through the cell (its lock and its status cache)."""

    def __init__(self, cell: CellJobs) -> None:
        self.cell = cell

    def on(self) -> None:
        self.cell.set_laser(True)

    def off(self) -> None:
        self.cell.set_laser(False)


def _raise_if_cancelled(cancel: threading.Event | None, what: str = "move") -> None:
    if cancel is not None and cancel.is_set():
        raise MotionRefusedError(f"{what} cancelled")
