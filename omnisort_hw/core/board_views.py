"""The board in each calibration view: found (with its per-corner checks) or rejected with the
reason, and when too few views show it, one error that groups the reasons and says what to
check (a board given by its squares instead of its inner corners is recognised)."""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from omnisort_hw.core.checkerboard import BoardDetection, BoardSpec, detect_board
from omnisort_hw.errors import CalibrationError, FeatureNotFoundError


@dataclass
class Rejection:
    name: str
    reason: str


@dataclass
class CornerRejection:
    """One corner left out of the fit: image, board index (row-major) and why."""

    name: str
    corner: int
    reason: str


def min_corners(n_board: int) -> int:
    """An image keeps its place while at least half of its board's corners are good."""
    return max(6, (n_board + 1) // 2)


def detect_views(
    grays: dict[str, np.ndarray],
    board: BoardSpec,
    need_images: int,
    on_detected: Callable[[str], None] | None = None,
) -> tuple[dict[str, BoardDetection], list[Rejection], list[CornerRejection]]:
    """Each view's board (dense scale search, in parallel), the rejected views and the corners
    left out at detection; CalibrationError when fewer than `need_images` views show it.
    `on_detected(name)` is called as each view is done (a progress bar)."""

    def detect(item: tuple[str, np.ndarray]) -> tuple[str, BoardDetection | Rejection]:
        name, gray = item
        try:
            found: BoardDetection | Rejection = detect_board(gray, board, dense=True)
        except FeatureNotFoundError as exc:
            found = Rejection(name, str(exc))
        if on_detected is not None:
            on_detected(name)
        return name, found

    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        detections = list(pool.map(detect, grays.items()))
    rejected = [d for _, d in detections if isinstance(d, Rejection)]
    found = {n: d for n, d in detections if isinstance(d, BoardDetection)}
    at_detection = [
        CornerRejection(n, k, reason) for n, d in found.items() for k, reason in d.rejected.items()
    ]
    need = min_corners(board.cols * board.rows)
    for name, det in list(found.items()):
        if int(det.good.sum()) < need:
            rejected.append(
                Rejection(name, f"only {int(det.good.sum())} corners pass the saddle check")
            )
            del found[name]
    if len(found) < need_images:
        hint = "" if found else _board_size_hint(next(iter(grays.values())), board)
        raise CalibrationError(
            f"only {len(found)} of {len(grays)} image(s) show the full {board.cols}x{board.rows} "
            f"board, at least {need_images} are needed{hint}" + _grouped_reasons(rejected)
        )
    return found, rejected, at_detection


def _grouped_reasons(rejected: list[Rejection], names_shown: int = 3) -> str:
    """The rejections grouped by reason, each with a few of its file names: one line per
    reason instead of the same sentence once per image."""
    groups: dict[str, list[str]] = {}
    for r in rejected:
        groups.setdefault(r.reason, []).append(Path(r.name).name)
    lines = []
    for reason, names in groups.items():
        shown = ", ".join(names[:names_shown])
        more = f" and {len(names) - names_shown} more" if len(names) > names_shown else ""
        lines.append(f"\n  {len(names)} image(s) ({shown}{more}): {reason}")
    return "".join(lines)


def _board_size_hint(gray: np.ndarray, board: BoardSpec) -> str:
    """When no image shows the board: whether the first one shows a board one corner larger
    or smaller each way (squares counted instead of inner corners, or the reverse)."""
    for cols, rows in ((board.cols - 1, board.rows - 1), (board.cols + 1, board.rows + 1)):
        if min(cols, rows) < 2:
            continue
        try:
            detect_board(gray, (cols, rows))
        except FeatureNotFoundError:
            continue
        return (
            f"; the first image shows a {cols}x{rows} board: --board counts inner corners "
            "(squares minus one each way)"
        )
    return ""
