"""Views for the intrinsic calibration, taken from the live camera: `add` grabs a frame, finds
the full checkerboard in it and keeps it (a PNG in the store's views folder and its board's
outline beside it); `list` gives the views kept and their coverage of the image circle;
`remove` and `clear` take views out. The intrinsics then calibrate from the folder
(`calibrate what=intrinsics folder=<the reply's folder>`), with their own dense detection.

A frame without the full board is not kept: the reply's error is the detector's reason, so
the person holding the board knows what to change. Coverage is the intrinsics report's: the
sectors of the image circle's outer band holding a corner of some view, the circle found from
the views' mean brightness about the image centre (there is no lens model yet).
"""

from __future__ import annotations

import functools
import json
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Protocol

import numpy as np

from omnisort_hw import fileio
from omnisort_hw.core.checkerboard import BoardSpec, detect_board, to_gray
from omnisort_hw.core.intrinsics import MIN_IMAGES
from omnisort_hw.core.intrinsics_report import (
    LOW_COVERAGE,
    OUTER_BAND,
    band_coverage,
    covered_fraction,
    image_circle_radius,
)
from omnisort_hw.core.overlays import encode_png
from omnisort_hw.errors import InputError
from omnisort_hw.pipeline.replies import CoverageReply, KeptViewReply, ViewsReply
from omnisort_hw.pipeline.requests import DEFAULT_SQUARE_MM, ViewsRequest, board_spec
from omnisort_hw.pipeline.verdict import Check, Verdict, at_least

NAME = re.compile(r"view_\d{3}")


class ViewsRig(Protocol):
    """What the views need of a cell (`cell.jobs.CellJobs` is one)."""

    @property
    def views_dir(self) -> Path: ...

    def live_frame(self) -> np.ndarray: ...


@dataclass(frozen=True)
class View:
    """One kept view: its image file, the board found in it, and when it was taken."""

    name: str
    image: Path
    board: str  # COLSxROWS
    corners_px: np.ndarray  # (cols*rows, 2) the board's inner corners, row by row
    circle_radius_px: float  # the lit image circle's radius about the image centre
    image_size: tuple[int, int]  # (width, height)
    taken: str

    def outline_px(self) -> np.ndarray:
        """(2 (cols + rows) - 4, 2): the board's outer corners, around."""
        cols, rows = (int(x) for x in self.board.split("x"))
        grid = self.corners_px.reshape(rows, cols, 2)
        ring = [grid[0, :], grid[1:, -1], grid[-1, -2::-1], grid[-2:0:-1, 0]]
        return np.concatenate(ring)


def _record(path: Path) -> View | None:
    """The view whose record is `path` (view_NNN.json), None when its image is missing."""
    data = json.loads(path.read_text(encoding="utf-8"))
    image = path.with_suffix(".png")
    if not image.exists():
        return None
    return View(
        path.stem,
        image,
        str(data["board"]),
        np.asarray(data["corners_px"], float).reshape(-1, 2),
        float(data["circle_radius_px"]),
        (int(data["image_size"][0]), int(data["image_size"][1])),
        str(data["taken"]),
    )


def kept_views(folder: Path) -> list[View]:
    """The views in `folder`, by name; a record that cannot be read is an InputError naming it."""
    views = []
    for path in sorted(folder.glob("view_*.json")):
        if not NAME.fullmatch(path.stem):
            continue
        try:
            view = _record(path)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InputError(f"{path}: not a view record ({exc}); remove the view") from None
        if view is not None:
            views.append(view)
    return views


def _next_name(folder: Path) -> str:
    numbers = [int(p.stem[5:]) for p in folder.glob("view_*.*") if NAME.fullmatch(p.stem)]
    return f"view_{max(numbers, default=0) + 1:03d}"


def add_view(folder: Path, image: np.ndarray, board: BoardSpec, taken: str) -> View:
    """Keep `image` ((H, W, 3) BGR) as the next view if the full `board` is in it, else
    FeatureNotFoundError with the detector's reason (nothing written). The image first, then
    its record: a view is listed only once both are whole."""
    size = f"{board.cols}x{board.rows}"
    held = {v.board for v in kept_views(folder)} - {size}
    if held:
        raise InputError(
            f"board: the views in {folder} show a {held.pop()} board, not {size}; clear them "
            "first (one calibration, one board)"
        )
    found = detect_board(image, board)
    gray = to_gray(image)
    h, w = gray.shape
    radius = image_circle_radius([gray], ((w - 1) / 2.0, (h - 1) / 2.0))
    folder.mkdir(parents=True, exist_ok=True)
    name = _next_name(folder)
    fileio.atomic_write_bytes(folder / f"{name}.png", encode_png(image), keep_history=False)
    record = {
        "board": size,
        "corners_px": np.round(found.corners, 3).tolist(),
        "circle_radius_px": round(radius, 1),
        "image_size": [w, h],
        "taken": taken,
    }
    fileio.atomic_write_bytes(
        folder / f"{name}.json", json.dumps(record).encode("utf-8"), keep_history=False
    )
    corners = np.asarray(record["corners_px"], float)  # as kept, so as listed later
    return View(
        name, folder / f"{name}.png", size, corners, record["circle_radius_px"], (w, h), taken
    )


def remove_views(folder: Path, name: str | None) -> list[str]:
    """Take out the view `name` (InputError if there is none), or every view (None)."""
    if name is not None and not NAME.fullmatch(name):
        raise InputError(f"name: {name!r} is not a view's name (view_001, view_002...)")
    names = [name] if name is not None else sorted({p.stem for p in folder.glob("view_*.*")})
    removed = []
    for n in names:
        files = [folder / f"{n}.json", folder / f"{n}.png"]
        if not any(f.exists() for f in files):
            raise InputError(f"name: no view {n} in {folder}")
        for f in files:  # the record first: a view without it is no longer listed
            f.unlink(missing_ok=True)
        removed.append(n)
    return removed


@dataclass(frozen=True)
class Coverage:
    """The views' corners over the image circle's outer band (`band_coverage`)."""

    centre: tuple[float, float]
    radius: float
    covered: np.ndarray  # (SECTORS,) bool: a view's corner reaches the sector
    inside: np.ndarray  # (SECTORS,) bool: the sector's middle lies inside the frame
    fraction: float  # of the sectors inside, those covered


@dataclass
class ViewsResult:
    """The views kept after a request, and what it added or removed."""

    folder: Path
    views: list[View]
    added: View | None = None
    removed: tuple[str, ...] = ()

    @functools.cached_property
    def coverage(self) -> Coverage | None:
        """The image circle's outer band: which of its sectors hold a corner of some view,
        and which lie inside the frame; None without views."""
        if not self.views:
            return None
        w, h = self.views[0].image_size
        centre = ((w - 1) / 2.0, (h - 1) / 2.0)
        radius = float(np.median([v.circle_radius_px for v in self.views]))
        corners = np.concatenate([v.corners_px for v in self.views])
        covered, inside = band_coverage(corners, centre, radius, (w, h))
        return Coverage(centre, radius, covered, inside, covered_fraction(covered, inside))

    def verdict(self) -> Verdict:
        """Enough views for the intrinsics, and the rim covered as their report asks."""
        checks = [
            at_least(
                "views with the full board",
                len(self.views),
                MIN_IMAGES,
                "fail",
                "add views: the whole board in the picture, at another place and angle",
            )
        ]
        cov = self.coverage
        if cov is not None:
            ok = cov.fraction >= LOW_COVERAGE
            checks.append(
                Check(
                    "outer band of the image circle covered",
                    "pass" if ok else "warn",
                    f"{cov.fraction:.0%}",
                    f">= {LOW_COVERAGE:.0%}, or a small projection sigma at the rim",
                    ""
                    if ok
                    else "add views with the board near the rim, where the band is red; or "
                    "calibrate: the intrinsics pass this check when their projection sigma at "
                    "the rim is small, which only the calibration can tell",
                )
            )
        return Verdict("views for the intrinsic calibration", tuple(checks))

    def reply(self) -> ViewsReply:
        first, cov = (self.views[0] if self.views else None), self.coverage
        return ViewsReply(
            folder=str(self.folder),
            count=len(self.views),
            need=MIN_IMAGES,
            views=[_view_reply(v) for v in self.views],
            verdict=self.verdict(),
            board=first.board if first else None,
            image_width=first.image_size[0] if first else None,
            image_height=first.image_size[1] if first else None,
            coverage=None
            if cov is None
            else CoverageReply(
                centre_px=[round(cov.centre[0], 1), round(cov.centre[1], 1)],
                radius_px=round(cov.radius, 1),
                outer_band=OUTER_BAND,
                covered=cov.covered.tolist(),
                inside=cov.inside.tolist(),
                fraction=round(cov.fraction, 3),
            ),
            added=self.added.name if self.added is not None else None,
            removed=list(self.removed) if self.removed else None,
        )


def _view_reply(view: View) -> KeptViewReply:
    return KeptViewReply(view.name, view.taken, np.round(view.outline_px(), 1).tolist())


def run(rig: ViewsRig, request: ViewsRequest) -> ViewsResult:
    """Add a view from a live frame, list, remove one, or clear them (see the module doc)."""
    folder = rig.views_dir
    if request.action == "add":
        board = board_spec(request.board, DEFAULT_SQUARE_MM, "board")
        taken = datetime.now(UTC).isoformat(timespec="seconds")
        added = add_view(folder, rig.live_frame(), board, taken)
        return ViewsResult(folder, kept_views(folder), added=added)
    removed: list[str] = []
    if request.action in ("remove", "clear") and folder.exists():
        removed = remove_views(folder, request.name if request.action == "remove" else None)
    elif request.action == "remove":
        raise InputError(f"name: no view {request.name} ({folder} holds none)")
    kept = kept_views(folder) if folder.exists() else []
    return ViewsResult(folder, kept, removed=tuple(removed))
