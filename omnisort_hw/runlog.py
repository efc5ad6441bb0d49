"""The one place that talks to rerun. Every stage logs plain numpy arrays through a RunLog.

One `.rrd` file per run. `RunLog(None)` (or `NullLog`) is a no-op, so stages can always log
without asking whether logging is on. The core never imports this module's dependencies:
stages receive a RunLog from the caller.
"""

from __future__ import annotations

import threading
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np


class RunLog:
    """Logs images, points, lines, scalars and text of one run to one `.rrd` file."""

    def __init__(self, path: str | Path | None, application_id: str = "omnisort") -> None:
        self.path: Path | None = None
        self._application_id = application_id
        self._stream: Any = None
        self._rec: Any = None
        self._rr: Any = None
        self._swap = threading.Lock()
        # A second recording everything is also logged to (the live view's gRPC server); it
        # outlives file changes (`reopen`).
        self.mirror: Any = None
        self.reopen(path)

    def reopen(self, path: str | Path | None) -> None:
        """Close the current file and go on in `path` (None: stop writing), in place, so every
        holder of this RunLog follows. Raises OSError when `path`'s folder cannot be made; this
        log is then off (no file).

        One rerun recording stream serves every file of this RunLog: only its file sink is
        swapped. The rerun SDK keeps memory for each stream it ever created (about 0.5 MB plus
        much of what was logged to it), so a stream per file grew a long-running service
        without bound."""
        with self._swap:
            old, self._rec, self.path = self._rec, None, None
            if isinstance(old, _Tee):
                old = old.file
            if old is not None:
                try:
                    old.flush()
                finally:
                    if path is None:
                        old.disconnect()
            if path is None:
                if self.mirror is not None:
                    self._rec = _Tee(None, self.mirror)
                return
            new_path = Path(path)
            new_path.parent.mkdir(parents=True, exist_ok=True)
            if self._stream is None:
                import rerun as rr

                self._rr = rr
                self._stream = rr.RecordingStream(self._application_id, recording_id=uuid.uuid4())
            self._stream.save(str(new_path))
            self._rec = self._stream if self.mirror is None else _Tee(self._stream, self.mirror)
            self.path = new_path

    def set_mirror(self, rec: Any) -> None:
        """Log everything to `rec` as well from now on (None: stop); the file goes on."""
        with self._swap:
            self.mirror = rec
            cur = self._rec.file if isinstance(self._rec, _Tee) else self._rec
            if rec is None:
                self._rec = cur
            else:
                import rerun as rr

                self._rr = rr
                self._rec = _Tee(cur, rec)

    @property
    def enabled(self) -> bool:
        return self._rec is not None

    def set_step(self, timeline: str, step: int) -> None:
        """Set the sequence index that following entries belong to (image number, pick number)."""
        rec = self._rec
        if rec is not None:
            rec.set_time(timeline, sequence=int(step))

    def image(self, entity: str, image: np.ndarray, bgr: bool = True) -> None:
        """Log an image; OpenCV's BGR order is converted to RGB."""
        rec = self._rec
        if rec is None:
            return
        img = np.asarray(image)
        if img.ndim == 3 and img.shape[2] == 3 and bgr:
            img = img[:, :, ::-1]
        rec.log(entity, self._rr.Image(np.ascontiguousarray(img)))

    def points2d(
        self,
        entity: str,
        points: np.ndarray,
        color: Sequence[int] | np.ndarray | None = None,
        radius: float = 2.0,
        labels: Sequence[str] | None = None,
    ) -> None:
        rec = self._rec
        if rec is None:
            return
        pts = np.asarray(points, dtype=np.float32).reshape(-1, 2)
        rec.log(entity, self._rr.Points2D(pts, colors=color, radii=radius, labels=labels))

    def points3d(
        self,
        entity: str,
        points: np.ndarray,
        color: Sequence[int] | np.ndarray | None = None,
        radius: float = 2.0,
    ) -> None:
        rec = self._rec
        if rec is None:
            return
        pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        rec.log(entity, self._rr.Points3D(pts, colors=color, radii=radius))

    def lines2d(
        self, entity: str, strips: Sequence[np.ndarray], color: Sequence[int] | None = None
    ) -> None:
        rec = self._rec
        if rec is None:
            return
        rec.log(
            entity,
            self._rr.LineStrips2D(
                [np.asarray(s, np.float32).reshape(-1, 2) for s in strips], colors=color
            ),
        )

    def lines3d(
        self, entity: str, strips: Sequence[np.ndarray], color: Sequence[int] | None = None
    ) -> None:
        rec = self._rec
        if rec is None:
            return
        rec.log(
            entity,
            self._rr.LineStrips3D(
                [np.asarray(s, np.float32).reshape(-1, 3) for s in strips], colors=color
            ),
        )

    def pose(self, entity: str, matrix: np.ndarray) -> None:
        """Log a 4x4 homogeneous transform (translation in mm) as the entity's frame."""
        rec = self._rec
        if rec is None:
            return
        m = np.asarray(matrix, dtype=float)
        rec.log(entity, self._rr.Transform3D(translation=m[:3, 3], mat3x3=m[:3, :3]))

    def scalar(self, entity: str, value: float) -> None:
        rec = self._rec
        if rec is None:
            return
        rec.log(entity, self._rr.Scalars(float(value)))

    def text(self, entity: str, text: str) -> None:
        """Log a document (parameters, a summary) as markdown/plain text."""
        rec = self._rec
        if rec is None:
            return
        rec.log(entity, self._rr.TextDocument(text))

    def event(self, entity: str, message: str, level: str = "INFO") -> None:
        rec = self._rec
        if rec is None:
            return
        rec.log(entity, self._rr.TextLog(message, level=level))

    def close(self) -> None:
        """Flush and close the file (`path` still names it); later calls are no-ops."""
        last = self.path
        self.reopen(None)
        self.path = last

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Tee:
    """The file's recording and the mirror as one: every call goes to both (file first)."""

    def __init__(self, file: Any, mirror: Any) -> None:
        self.file, self.mirror = file, mirror

    def log(self, *args: Any, **kwargs: Any) -> None:
        if self.file is not None:
            self.file.log(*args, **kwargs)
        self.mirror.log(*args, **kwargs)

    def set_time(self, *args: Any, **kwargs: Any) -> None:
        if self.file is not None:
            self.file.set_time(*args, **kwargs)
        self.mirror.set_time(*args, **kwargs)

    def flush(self) -> None:
        if self.file is not None:
            self.file.flush()


NullLog = RunLog(None)


def entity_paths(rrd_path: str | Path) -> set[str]:
    """Entity paths stored in an `.rrd` file (used by tests and `omnisort review --list`)."""
    from rerun.chunk import RrdReader

    return {str(chunk.entity_path) for chunk in RrdReader(str(rrd_path)).stream()}
