"""Calibration storage: the current `camera.json` and `system.json` under the state directory.

Each file is the calibration payload produced by the core (its own top-level keys, untouched, so
`system.json` still compares key by key with the simulator's `truth.json`) plus two keys added
here:

    "storage":  {"format": 1, "kind": "camera"|"system", "camera_serial": ..., "saved": ISO time}
    "checksum": "sha256:<hex>" of the canonical JSON of every other key

Writes go through `fileio.atomic_write_json` (temp file, fsync, rename, fsync of the directory)
and keep a bounded number of previous versions in `history/`. A file that is missing, does not
parse, fails its checksum, lacks a required key, is older than the configured age or was made
with another camera blocks every motion; `status()` reports which and why.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypedDict

from omnisort_hw import fileio
from omnisort_hw.config.storage import StorageConfig
from omnisort_hw.core.camera_io import MODEL_KEYS
from omnisort_hw.errors import CalibrationFileError, MotionRefusedError, StorageError

if TYPE_CHECKING:
    from omnisort_hw.core.camera_model import OcamModel

FORMAT_VERSION = 1
Kind = Literal["camera", "system"]
KINDS: tuple[Kind, ...] = ("camera", "system")
FILE_NAMES: dict[str, str] = {"camera": "camera.json", "system": "system.json"}
META_KEY = "storage"
CHECKSUM_KEY = "checksum"

# Top-level keys the core's payloads must carry: camera.json is the core's OCam model dict
# (`camera_io.MODEL_KEYS`, plus its calibration record); system.json has the shared keys of the
# architecture, of which `robot_base` ("when known": after register_robot) and `image` may be
# absent. Deeper checks of the model belong to `OcamModel.from_dict` (`camera_model()`).
REQUIRED_KEYS: dict[str, tuple[str, ...]] = {
    "camera": MODEL_KEYS,
    "system": (
        "camera",
        "camera_rotation",
        "laser_plane",
        "target",
        "method",
        "residuals",
        "std",
        "created",
    ),
}
OPTIONAL_KEYS: dict[str, tuple[str, ...]] = {"camera": (), "system": ("robot_base", "image")}

Health = Literal["ok", "missing", "corrupt", "stale", "wrong_serial"]


def _json_default(obj: object) -> Any:
    """Serialise numpy arrays and scalars (the core hands over plain arrays) as JSON values."""
    tolist = getattr(obj, "tolist", None)
    if callable(tolist):
        return tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot store a {type(obj).__name__} in a calibration file")


def canonical_bytes(body: Mapping[str, object]) -> bytes:
    """The bytes the checksum covers: sorted keys, no whitespace, UTF-8."""
    return json.dumps(
        body, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=_json_default
    ).encode("utf-8")


def checksum_of(body: Mapping[str, object]) -> str:
    """`sha256:<hex>` of the canonical JSON of `body` (which must not contain the checksum)."""
    return "sha256:" + hashlib.sha256(canonical_bytes(body)).hexdigest()


def _parse_time(text: Any) -> datetime | None:
    if not isinstance(text, str):
        return None
    try:
        stamp = datetime.fromisoformat(text)
    except ValueError:
        return None
    return stamp if stamp.tzinfo is not None else stamp.replace(tzinfo=UTC)


@dataclass(frozen=True)
class CalibrationRecord:
    """A calibration file read back and verified: the core's payload and the storage metadata."""

    kind: str
    path: Path
    payload: dict[str, Any]
    camera_serial: str | None
    saved: datetime
    checksum: str


class _Stamp(TypedDict):
    """The `FileHealth` fields of a file that could be read (what `status()` passes to each)."""

    saved: str
    age_days: float
    camera_serial: str | None
    checksum: str
    history: int


@dataclass(frozen=True)
class FileHealth:
    """What `status()` says about one calibration file."""

    kind: str
    path: str
    health: Health
    message: str
    saved: str | None = None
    age_days: float | None = None
    camera_serial: str | None = None
    checksum: str | None = None
    history: int = 0

    @property
    def ok(self) -> bool:
        return self.health == "ok"


@dataclass
class CalibrationStore:
    """Reads and writes the cell's calibration files under one state directory.

    `expected_serial` is the serial of the camera now attached (from the device, or the
    configuration); None disables the serial check. `clock` returns UNIX seconds (tests move it).
    """

    state_dir: Path
    max_age_days: float | None = None
    history_keep: int = 20
    expected_serial: str | None = None
    clock: Callable[[], float] = field(default=time.time, repr=False)

    @classmethod
    def from_config(
        cls, config: StorageConfig, camera_serial: str | None = None
    ) -> CalibrationStore:
        """A store for `config`; the configured serial wins over the one the device reports."""
        return cls(
            state_dir=Path(config.state_dir),
            max_age_days=config.max_age_days,
            history_keep=config.history_keep,
            expected_serial=config.camera_serial or camera_serial,
        )

    def path(self, kind: str) -> Path:
        """Where the current file of `kind` ("camera" or "system") lives."""
        if kind not in FILE_NAMES:
            raise ValueError(f"unknown calibration kind {kind!r}; expected one of {KINDS}")
        return Path(self.state_dir) / FILE_NAMES[kind]

    # -- writing ---------------------------------------------------------------------------

    def save(
        self, kind: str, payload: Mapping[str, object], camera_serial: str | None = None
    ) -> Path:
        """Write `payload` as the current calibration of `kind`, keeping the previous version.

        The payload's own keys are stored as they are; `storage` and `checksum` are added.
        `camera_serial` defaults to the store's expected serial.
        """
        path = self.path(kind)
        if not isinstance(payload, Mapping) or not payload:
            raise CalibrationFileError(f"{path}: refusing to save an empty {kind} calibration")
        reserved = {META_KEY, CHECKSUM_KEY} & set(payload)
        if reserved:
            raise CalibrationFileError(
                f"{path}: the payload must not contain the reserved key(s) {sorted(reserved)}"
            )
        missing = [k for k in REQUIRED_KEYS[kind] if k not in payload]
        if missing:
            raise CalibrationFileError(
                f"{path}: refusing to save a {kind} calibration without {', '.join(missing)}"
            )
        serial = camera_serial if camera_serial is not None else self.expected_serial
        saved = datetime.fromtimestamp(self.clock(), UTC).isoformat(timespec="microseconds")
        body: dict[str, Any] = json.loads(canonical_bytes(payload))
        body[META_KEY] = {
            "format": FORMAT_VERSION,
            "kind": kind,
            "camera_serial": serial,
            "saved": saved,
        }
        body[CHECKSUM_KEY] = checksum_of(body)
        try:
            return fileio.atomic_write_json(
                path, body, keep_history=True, history_keep=self.history_keep
            )
        except OSError as exc:
            raise StorageError(
                f"{path}: the {kind} calibration could not be saved: {fileio.os_error_text(exc)}; "
                f"the current file and {fileio.history_dir(path)} are unchanged"
            ) from exc

    def save_camera(self, payload: Mapping[str, object], camera_serial: str | None = None) -> Path:
        """Save the camera intrinsics (the OCam model dict) as `camera.json`."""
        return self.save("camera", payload, camera_serial)

    def save_system(self, payload: Mapping[str, object], camera_serial: str | None = None) -> Path:
        """Save the system calibration as `system.json`."""
        return self.save("system", payload, camera_serial)

    def remove_stale_temps(self) -> list[Path]:
        """Delete temp files left by a write that was killed (call once at start-up)."""
        return fileio.remove_stale_temps(self.state_dir)

    # -- reading ---------------------------------------------------------------------------

    def read(self, kind: str) -> CalibrationRecord:
        """Read and verify the file of `kind` (JSON, checksum, metadata, required keys).

        Raises CalibrationFileError naming the file and what is wrong. Age and serial are not
        checked here: see `check()`.
        """
        path = self.path(kind)
        return read_calibration_file(path, kind)

    def load(self, kind: str) -> dict[str, Any]:
        """The verified payload of `kind` (without the storage keys)."""
        return self.read(kind).payload

    def load_camera(self) -> dict[str, Any]:
        """The verified camera intrinsics payload from `camera.json`."""
        return self.load("camera")

    def load_system(self) -> dict[str, Any]:
        """The verified system calibration payload from `system.json`."""
        return self.load("system")

    def camera_model(self) -> OcamModel:
        """The verified camera.json as the core's OcamModel (model keys checked by the core)."""
        from omnisort_hw.core.camera_model import OcamModel
        from omnisort_hw.errors import InputError

        rec = self.read("camera")
        try:
            return OcamModel.from_dict(rec.payload, source=str(rec.path))
        except InputError as exc:
            raise CalibrationFileError(str(exc)) from None

    def history(self, kind: str) -> list[Path]:
        """Previous versions of `kind`, oldest first."""
        return fileio.history_versions(self.path(kind))

    def check(self, kind: str) -> FileHealth:
        """Health of one file: ok, missing, corrupt, stale or wrong_serial, with a message."""
        path = self.path(kind)
        n_hist = len(self.history(kind))
        if not path.exists():
            return FileHealth(
                kind, str(path), "missing", f"{path}: no {kind} calibration yet", history=n_hist
            )
        try:
            rec = self.read(kind)
        except CalibrationFileError as exc:
            return FileHealth(kind, str(path), "corrupt", str(exc), history=n_hist)
        age_days = (self.clock() - rec.saved.timestamp()) / 86400.0
        common: _Stamp = {
            "saved": rec.saved.isoformat(),
            "age_days": round(age_days, 4),
            "camera_serial": rec.camera_serial,
            "checksum": rec.checksum,
            "history": n_hist,
        }
        if self.expected_serial is not None and rec.camera_serial != self.expected_serial:
            return FileHealth(
                kind,
                str(path),
                "wrong_serial",
                f"{path}: made with camera serial {rec.camera_serial!r}, but the camera is "
                f"{self.expected_serial!r}; recalibrate",
                **common,
            )
        if self.max_age_days is not None and age_days > self.max_age_days:
            return FileHealth(
                kind,
                str(path),
                "stale",
                f"{path}: {age_days:.1f} days old, older than the configured "
                f"{self.max_age_days:g} days; recalibrate",
                **common,
            )
        return FileHealth(kind, str(path), "ok", f"{path}: ok", **common)

    def check_motion_allowed(self, require_robot_base: bool = False) -> None:
        """Raise MotionRefusedError (with each file's problem) unless both files are healthy.

        With `require_robot_base`, system.json must also hold the robot's base pose (what
        motions planned from the camera need: sorting, picking).
        """
        problems = [h for h in (self.check(k) for k in KINDS) if not h.ok]
        if problems:
            raise MotionRefusedError(
                "motion refused: calibration not usable: "
                + "; ".join(f"{h.kind} {h.health}: {h.message}" for h in problems)
            )
        if require_robot_base and not self.robot_registered():
            raise MotionRefusedError(
                f"motion refused: {self.path('system')} has no robot_base: run register_robot"
            )

    def robot_registered(self) -> bool:
        """True when a valid system.json holds a robot base pose."""
        try:
            return isinstance(self.load_system().get("robot_base"), dict)
        except CalibrationFileError:
            return False

    def status(self) -> dict[str, Any]:
        """A summary for the service's `status` reply: per-file health and `motion_allowed`."""
        files = {k: asdict(self.check(k)) for k in KINDS}
        return {
            "state_dir": str(self.state_dir),
            "max_age_days": self.max_age_days,
            "expected_camera_serial": self.expected_serial,
            "motion_allowed": all(f["health"] == "ok" for f in files.values()),
            "robot_registered": self.robot_registered(),
            "files": files,
        }


def read_calibration_file(path: str | Path, kind: str) -> CalibrationRecord:
    """Read one calibration file and verify it; CalibrationFileError says what is wrong."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise CalibrationFileError(f"{path}: missing (no {kind} calibration saved yet)") from None
    except OSError as exc:
        raise CalibrationFileError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise CalibrationFileError(f"{path}: corrupt, not valid JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise CalibrationFileError(f"{path}: corrupt, top level is not a JSON object")
    stored = doc.pop(CHECKSUM_KEY, None)
    if not isinstance(stored, str):
        raise CalibrationFileError(
            f"{path}: no checksum; not written by omnisort storage (a file made by the "
            "command line is taken in with `omnisort ctl adopt camera=... system=...`)"
        )
    actual = checksum_of(doc)
    if stored != actual:
        raise CalibrationFileError(
            f"{path}: corrupt, checksum mismatch "
            f"(stored {stored[:19]}..., content {actual[:19]}...)"
        )
    meta = doc.pop(META_KEY, None)
    if not isinstance(meta, dict):
        raise CalibrationFileError(f"{path}: the '{META_KEY}' metadata object is missing")
    if meta.get("format") != FORMAT_VERSION:
        raise CalibrationFileError(
            f"{path}: storage format {meta.get('format')!r}, this version reads {FORMAT_VERSION}"
        )
    if meta.get("kind") != kind:
        raise CalibrationFileError(
            f"{path}: holds a {meta.get('kind')!r} calibration, not {kind!r}"
        )
    saved = _parse_time(meta.get("saved"))
    if saved is None:
        raise CalibrationFileError(f"{path}: the save time {meta.get('saved')!r} is not ISO 8601")
    serial = meta.get("camera_serial")
    if serial is not None and not isinstance(serial, str):
        raise CalibrationFileError(f"{path}: camera_serial must be a string or null")
    if not doc:
        raise CalibrationFileError(f"{path}: the {kind} calibration payload is empty")
    missing = [k for k in REQUIRED_KEYS.get(kind, ()) if k not in doc]
    if missing:
        raise CalibrationFileError(f"{path}: required key(s) missing: {', '.join(missing)}")
    return CalibrationRecord(kind, path, doc, serial, saved, stored)
