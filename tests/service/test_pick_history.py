"""The page's pick log across sorts (`status_reading.PickHistory`): a stop and a resume keep
the first sort's picks, numbered on from them; each sort's own cube numbers stay as its
location gave them."""

from __future__ import annotations

from typing import Any

from omnisort_hw.service.status_reading import PickHistory


def status(started: str, cubes: list[tuple[int, str]], job: str = "sort") -> dict[str, Any]:
    progress: list[dict[str, Any]] = [{"to_pick": len(cubes)}]
    progress += [
        {"cube": c, "status": outcome, "color": "red", "bin": "red", "at": started}
        for c, outcome in cubes
    ]
    return {"last_run": {"job": job, "started": started, "progress": progress}}


def test_a_resumed_sort_numbers_on_from_the_stopped_one() -> None:
    history = PickHistory()
    assert history.update({"last_run": None}) == []
    # A sort refused before it picked (no bin for a colour) is no sort of the log.
    assert history.update(status("2026-12-07T09:59:00+00:00", [])) == []
    first = status("2026-12-07T10:00:00+00:00", [(0, "sorted")])
    assert [(n, k, r.cube) for n, k, r in history.update(first)] == [(1, 1, 0)]
    # The same sort read again, then stopped: the same rows.
    assert [(n, k, r.cube) for n, k, r in history.update(first)] == [(1, 1, 0)]
    # A locate between them is no sort: the log stays.
    locate = {"last_run": {"job": "locate", "started": "2026-12-07T10:01:00+00:00"}}
    assert len(history.update(locate)) == 1
    resumed = status("2026-12-07T10:02:00+00:00", [(0, "sorted"), (1, "skipped")])
    rows = history.update(resumed)
    assert [(n, k, r.cube, r.outcome) for n, k, r in rows] == [
        (1, 1, 0, "sorted"),
        (2, 2, 0, "sorted"),
        (3, 2, 1, "skipped"),
    ]


def test_only_the_last_sorts_are_kept() -> None:
    history = PickHistory(keep=2)
    for minute in range(4):
        rows = history.update(status(f"2026-12-07T10:0{minute}:00+00:00", [(0, "sorted")]))
    assert [(n, k) for n, k, _ in rows] == [(1, 1), (2, 2)]
    assert list(history.runs) == ["2026-12-07T10:02:00+00:00", "2026-12-07T10:03:00+00:00"]
