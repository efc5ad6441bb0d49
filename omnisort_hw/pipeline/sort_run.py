"""The sort use case, `run(rig, SortRequest)`: the same gates and the same run from every door.

Before anything opens: a usable calibration (present, intact, recent, for this camera) and no
drift of it on record. Then, with the rig's devices held for the run: a cube left in the
gripper by an interrupted run is placed first (from the job journal), every pick phase is
journalled, and `Sorter` sorts. The service's cell and the CLI's file rig differ only in how
they hold their devices (`SortRig.sorting`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.errors import NotAvailableError
from omnisort_hw.pipeline.calibration_source import CalibrationSource, robot_base_T
from omnisort_hw.pipeline.gripper_load import InFlightJournal, resolve_before_sort
from omnisort_hw.pipeline.pick_cycle import Compute
from omnisort_hw.pipeline.requests import SortRequest
from omnisort_hw.pipeline.sort import Sorter, SortVerifier
from omnisort_hw.pipeline.sort_report import SortReport
from omnisort_hw.request_fields import ArgumentError
from omnisort_hw.runlog import RunLog

if TYPE_CHECKING:
    from drivers.base import Arm, Camera, LaserSwitch


class SortJournal(InFlightJournal, Protocol):
    """The job journal as a sort writes it: each pick's phase, and the cube in flight."""

    def pick_phase(self, phase: str, cube: int, color: str, bin_: str | None) -> None: ...


@dataclass
class SortSession:
    """The devices a sort runs on, held by the rig for the run, and how it captures."""

    camera: Camera
    laser: LaserSwitch | None
    arm: Arm
    journal: SortJournal
    compute: Compute | None = None  # the service's compute worker; None: in this process
    acquire: Callable[[], tuple[np.ndarray, np.ndarray | None, dict[str, Any]]] | None = None
    verifier: SortVerifier | None = None  # the simulated cell's truth, where there is one
    clock: Callable[[], float] | None = None  # the arm's time where it is not the PC's


class NoJournal:
    """A journal that keeps nothing: a run whose cell ends with it (an evaluation's scene)."""

    def pick_phase(self, phase: str, cube: int, color: str, bin_: str | None) -> None:
        return None

    def in_flight(self) -> dict[str, Any] | None:
        return None

    def clear_in_flight(self, why: str) -> None:
        return None


class SortRig(Protocol):
    """A rig that can sort: its `[sorting]` and `[registration]`, its run log, its calibration
    as a motion gate, its drift record, its devices."""

    @property
    def sort_config(self) -> SortConfig | None: ...

    def laser_color(self) -> str: ...

    @property
    def registration_config(self) -> RegistrationConfig | None: ...

    @property
    def runlog(self) -> RunLog: ...

    def calibration_source(self) -> CalibrationSource: ...

    def check_drift(self) -> None:
        """CalibrationDriftError when a drift of the calibration is on record."""
        ...

    def sorting(self, request: SortRequest) -> AbstractContextManager[SortSession]:
        """The devices connected and held (and the job journalled) for one sort."""
        ...


def run(
    rig: SortRig,
    request: SortRequest,
    cancel: threading.Event | None = None,
    progress: Callable[[dict[str, Any]], None] | None = None,
) -> SortReport:
    """Sort until done, `request.max_objects` or `cancel` (see the module doc)."""
    cfg = rig.sort_config
    if cfg is None:
        raise NotAvailableError(
            "the sorting pipeline needs a [sorting] section in the cell configuration (bins, "
            "obstacles, cube size, home pose; or from_scene = true)"
        )
    binless = [c for c in request.colors or () if cfg.bin_for(c) is None]
    if binless:  # every cube would be skipped: refused before anything moves
        raise ArgumentError(
            "colors",
            f"sort: argument 'colors': no bin for {', '.join(binless)} (the cell's bins: "
            + ", ".join(b.color for b in cfg.bins)
            + ")",
        )
    calibration = rig.calibration_source()
    calibration.check_motion_allowed()
    rig.check_drift()
    with rig.sorting(request) as session:
        journal = session.journal
        sorter = Sorter(
            session.camera,
            session.arm,
            session.laser,
            calibration,
            cfg,
            rig.registration_config,
            log=rig.runlog,
            cancel=cancel,
            progress=progress,
            on_pick=lambda phase, o: journal.pick_phase(phase, o.index, o.color, o.bin),
            compute=session.compute,
            acquire=session.acquire,
            laser_color=rig.laser_color(),
            clock=session.clock,
        )
        system = calibration.system()
        held = None
        if system.robot_base is not None or not request.register:
            held = resolve_before_sort(sorter, journal, robot_base_T(system))
        verifier = session.verifier
        report = sorter.run(
            request.max_objects,
            list(request.colors) if request.colors is not None else None,
            register=request.register,
            on_located=verifier.on_located if verifier is not None else None,
            on_done=verifier.on_done if verifier is not None else None,
        )
        if held is not None:
            report.outcomes.insert(0, held)
    return report
