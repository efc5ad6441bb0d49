"""The cell's drift watchdog: runs the drift check, keeps its last result and refuses motion
after a detected drift until the calibration changes or an operator acknowledges it.

The state lives in `STATE_DIR/drift.json` (atomic writes), so a restart does not forget a
detected drift. A drift belongs to the calibration it was measured against (its key): a new
extrinsic calibration or robot registration clears it by itself. The watchdog sees its cell
only through `WatchdogPorts`: the store, a capture with the laser off, the registration
settings and the current run log.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw import fileio
from omnisort_hw.config.sorting import RegistrationConfig
from omnisort_hw.config.watchdog import WatchdogConfig
from omnisort_hw.errors import CalibrationDriftError, FeatureNotFoundError, InputError
from omnisort_hw.pipeline import drift_check
from omnisort_hw.pipeline.calibration_store import CalibrationStore
from omnisort_hw.pipeline.drift_check import (
    DRIFT_STATE_NAME,
    calibration_key,
    drift_refusal,
    load_drift_state,
    load_reference,
    save_reference,
)
from omnisort_hw.pipeline.replies import AcknowledgeReply, DriftReply
from omnisort_hw.pipeline.requests import CheckRequest
from omnisort_hw.runlog import RunLog
from omnisort_hw.wire_records import to_wire

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WatchdogPorts:
    """What the watchdog needs of its cell: the calibration store, a frame with the laser off,
    the `[registration]` settings and the run log of the moment (it rotates)."""

    store: CalibrationStore
    capture_dark: Callable[[], np.ndarray]
    registration: Callable[[], RegistrationConfig | None]
    runlog: Callable[[], RunLog]


@dataclass(frozen=True)
class _PortsRig:
    """The watchdog's ports as the drift check's rig (`drift_check.CheckRig`)."""

    ports: WatchdogPorts
    watchdog_config: WatchdogConfig

    @property
    def runlog(self) -> RunLog:
        return self.ports.runlog()

    @property
    def registration_config(self) -> RegistrationConfig | None:
        return self.ports.registration()

    def system_record(self) -> tuple[dict[str, Any], str]:
        record = self.ports.store.read("system")
        return record.payload, str(record.path)

    def grab_frame(self, laser: bool) -> np.ndarray:
        return self.ports.capture_dark()

    def drift_reference(self, key: str) -> np.ndarray | None:
        return load_reference(self.ports.store.state_dir, key)


class DriftWatchdog:
    """Drift checks of one cell: on request, before each sort, every `period_s` when idle."""

    def __init__(self, ports: WatchdogPorts, config: WatchdogConfig | None = None) -> None:
        self.ports = ports
        self.config = config or WatchdogConfig()
        self._lock = threading.Lock()
        self._path = Path(ports.store.state_dir) / DRIFT_STATE_NAME
        self._state: dict[str, Any] = self._load()
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        # Set by the service: True while a job runs (the periodic check then waits).
        self.busy: Callable[[], bool] = lambda: False

    @property
    def store(self) -> CalibrationStore:
        return self.ports.store

    # -- state -------------------------------------------------------------------------------

    def _load(self) -> dict[str, Any]:
        return load_drift_state(self._path.parent)

    def _save(self) -> None:
        try:
            fileio.atomic_write_json(self._path, self._state, keep_history=False)
        except OSError as exc:
            log.error("drift watchdog: cannot write %s: %s", self._path, exc)

    def _current_key(self) -> str | None:
        try:
            return calibration_key(self.store.read("system").payload)
        except Exception:
            return None

    def refusal(self) -> str | None:
        """Why motion is refused now (a drift of the current calibration not acknowledged)."""
        with self._lock:
            st = dict(self._state)
        return drift_refusal(st, self._current_key())

    def check_motion_allowed(self) -> None:
        why = self.refusal()
        if why is not None:
            raise CalibrationDriftError(why)

    def status(self) -> dict[str, Any]:
        """`status.drift`: the last check, the drift that refuses motion (if any)."""
        with self._lock:
            st = dict(self._state)
        why = self.refusal()
        return {
            "last": st.get("last"),
            "motion_refused": why is not None,
            "reason": why,
            "acknowledged": st.get("acknowledged"),
            "period_s": self.config.period_s,
            "last_error": st.get("last_error"),
        }

    def acknowledge(self) -> AcknowledgeReply:
        """An operator accepts the drift (e.g. checked the picks by hand): motion allowed again
        until the next check finds drift."""
        with self._lock:
            drift = self._state.get("drift_detected")
            self._state["acknowledged"] = (
                {
                    "at": datetime.now(UTC).isoformat(timespec="seconds"),
                    "angle_deg": drift["angle_deg"],
                }
                if drift
                else None
            )
            self._save()
        self.ports.runlog().event("drift/check", "drift acknowledged by an operator", level="WARN")
        return AcknowledgeReply(acknowledged=drift is not None, drift=drift)

    # -- checks ------------------------------------------------------------------------------

    def save_reference(self, image: np.ndarray) -> None:
        """The registration's capture becomes the reference of the calibration just saved."""
        try:
            key = calibration_key(self.store.read("system").payload)
            save_reference(self.store.state_dir, image, key)
        except Exception as exc:
            log.error("drift watchdog: cannot save the reference image: %s", exc)

    def check(self, image: str | None = None) -> DriftReply:
        """The drift check use case on `image` (or a laser-off capture); its result recorded."""
        rig = _PortsRig(self.ports, self.config)
        result = drift_check.run(rig, CheckRequest(image))
        summary = result.reply()
        if result.decision.source == "board" and not result.drift and image is None:
            # No reference for this calibration yet (registered elsewhere), so the board alone
            # measured: it found no drift, so this capture becomes the reference of the finer
            # image check.
            assert result.frame is not None
            save_reference(self.store.state_dir, result.frame, result.key)
            summary = replace(summary, reference_adopted=True)
        with self._lock:
            self._state["last"] = to_wire(summary)
            if result.drift:
                self._state["drift_detected"] = to_wire(summary)
                self._state["acknowledged"] = None
            self._save()
        if result.drift:
            log.warning("drift: %s", self.refusal())
        return summary

    def before_sort(self) -> None:
        """The check `sort` runs first (when configured); raises on drift."""
        if self.config.before_sort:
            try:
                self.check()
            except (FeatureNotFoundError, InputError) as exc:
                # Nothing to measure with (board hidden and no reference): not a drift; the
                # sort's own registration and location checks still apply.
                log.warning("drift check before sort could not measure: %s", exc)
                with self._lock:
                    self._state["last_error"] = f"{type(exc).__name__}: {exc}"
        self.check_motion_allowed()

    # -- periodic ----------------------------------------------------------------------------

    def start(self) -> None:
        if self.config.period_s <= 0 or self._thread is not None:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="drift-watchdog", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None

    def _run(self) -> None:
        next_at = time.monotonic() + self.config.period_s
        while not self._stop.wait(min(1.0, max(0.0, next_at - time.monotonic()))):
            if time.monotonic() < next_at or self.busy():
                continue
            next_at = time.monotonic() + self.config.period_s
            try:
                self.check()
            except Exception as exc:
                log.warning("periodic drift check failed: %s", exc)
                with self._lock:
                    self._state["last_error"] = f"{type(exc).__name__}: {exc}"
