"""The calibration's history: the current camera.json or system.json and every version the
store kept before it (`history/NAME.TIMESTAMP`, written by each save), each verified (its
checksum) and summed up, newest first, so a person can pick the one to go back to. Going
back is `adopt` with that version's path: it is verified against the cell and saved as the
current one, the current one kept in the history in its turn.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from omnisort_hw.errors import CalibrationFileError
from omnisort_hw.pipeline.calibration_store import CalibrationStore, read_calibration_file
from omnisort_hw.pipeline.replies import HistoryReply, VersionReply
from omnisort_hw.pipeline.requests import HistoryRequest


class HistoryRig(Protocol):
    @property
    def store(self) -> CalibrationStore: ...


def summary(kind: str, payload: dict[str, Any]) -> str:
    """What tells two versions apart, in a line."""
    if kind == "camera":
        rms = payload.get("rms_px")
        used = payload.get("images_used")
        views = len(used) if isinstance(used, list) else used
        return f"RMS {rms:.3f} px over {views} views" if rms is not None else "camera model"
    method = payload.get("method", "?")
    laser = payload.get("laser_plane") or {}
    distance = laser.get("distance_mm")
    text = f"method {method}"
    if distance is not None:
        text += f", laser at {float(distance):.2f} mm"
    return text + (", robot registered" if payload.get("robot_base") else ", robot not registered")


def _version(path: Path, kind: str, current: bool) -> VersionReply:
    try:
        rec = read_calibration_file(path, kind)
    except CalibrationFileError as exc:
        return VersionReply(str(path), current, problem=str(exc))
    return VersionReply(
        str(path),
        current,
        saved=rec.saved.isoformat(),
        checksum=rec.checksum,
        summary=summary(kind, rec.payload),
    )


@dataclass(frozen=True)
class HistoryResult:
    kind: str
    versions: tuple[VersionReply, ...]

    def reply(self) -> HistoryReply:
        return HistoryReply(self.kind, list(self.versions))


def run(rig: HistoryRig, request: HistoryRequest) -> HistoryResult:
    """The current file of the request's kind (when there is one) and its kept versions,
    newest first; a version that does not verify says why instead of its figures."""
    store = rig.store
    path = store.path(request.kind)
    versions = [_version(path, request.kind, True)] if path.exists() else []
    versions += [_version(p, request.kind, False) for p in reversed(store.history(request.kind))]
    return HistoryResult(request.kind, tuple(versions))
