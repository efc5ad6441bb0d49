"""A simulated scene as the sort use case's rig: the evaluations sort through
`pipeline.sort_run.run`, the same gates and run as the CLI and the service, on devices they hold
for one scene, with the calibration under test in memory and the simulator's truth as verifier.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.core.pick_planning import SortConfig
from omnisort_hw.pipeline import sort_run
from omnisort_hw.pipeline.calibration_source import MemoryCalibration
from omnisort_hw.pipeline.requests import SortRequest
from omnisort_hw.pipeline.sort_report import SortReport
from omnisort_hw.pipeline.sort_run import NoJournal, SortSession
from omnisort_hw.runlog import NullLog, RunLog
from sim_backend.devices import SimArm, SimCamera, SimLaserSwitch
from sim_backend.sort_harness import SimVerifier


@dataclass
class SceneRig:
    """One scene's connected devices and the calibration under test (`sort_run.SortRig`); no
    drift on record (each scene is calibrated afresh), no journal (the cell ends with the
    scene)."""

    sort_config: SortConfig
    registration_config: RegistrationConfig | None
    runlog: RunLog
    calibration: MemoryCalibration
    session: SortSession

    def calibration_source(self) -> MemoryCalibration:
        return self.calibration

    def laser_color(self) -> str:
        """The scene's laser, drawn red (sim_backend.scene.LaserSpec)."""
        return "red"

    def check_drift(self) -> None:
        return None

    @contextmanager
    def sorting(self, request: SortRequest) -> Iterator[SortSession]:
        verifier = self.session.verifier
        if isinstance(verifier, SimVerifier):
            verifier.start()
        try:
            yield self.session
        finally:
            if isinstance(verifier, SimVerifier):
                verifier.stop()


def sort_on_scene(
    devices: tuple[SimCamera, SimLaserSwitch, SimArm],
    calibration: MemoryCalibration,
    cfg: SortConfig,
    registration: RegistrationConfig | None,
    verifier: SimVerifier,
    log: RunLog = NullLog,
    clock: Callable[[], float] | None = None,
) -> SortReport:
    """Register the robot from the first capture and sort every cube of the scene, checked
    against its truth (the devices connected by the caller)."""
    camera, laser, arm = devices
    session = SortSession(camera, laser, arm, NoJournal(), verifier=verifier, clock=clock)
    rig = SceneRig(cfg, registration, log, calibration, session)
    return sort_run.run(rig, SortRequest(register=True))
