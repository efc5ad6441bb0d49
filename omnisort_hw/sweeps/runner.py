"""Run a sweep: open (or resume) its store, run the unfinished trials on an executor, write
each row as it finishes, return all rows in the manifest's order.

Without a directory the rows are kept in memory only (the library calls of the evaluations,
`evaluate_sorting` and the like, run that way on the serial executor).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from omnisort_hw.sweeps.executors import SerialExecutor
from omnisort_hw.sweeps.provenance import git_revision, package_versions
from omnisort_hw.sweeps.store import SweepStore
from omnisort_hw.sweeps.trial import Trial, run_trial


@dataclass
class SweepRun:
    """A sweep's rows (manifest order) and how many trials this run computed."""

    rows: list[dict[str, Any]]
    ran: int
    resumed: int


def run_sweep(
    trials: Sequence[Trial],
    directory: str | os.PathLike[str] | None = None,
    executor: Any = None,
    progress: bool = False,
    on_row: Callable[[dict[str, Any]], None] | None = None,
    desc: str = "trials",
) -> SweepRun:
    """Run `trials` (see module docstring). `executor`: a SerialExecutor, PoolExecutor or
    DaskExecutor (serial by default; the caller owns it). `on_row`: called with each new row
    as it finishes (in finishing order). A trial that raises stops the sweep; the rows
    written so far stay, and running it again resumes after them."""
    from tqdm import tqdm

    executor = executor or SerialExecutor()
    store = SweepStore(directory) if directory is not None else None
    meta = {
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "git": git_revision(),
        "packages": package_versions(),
    }
    done = store.open(trials, meta) if store is not None else {}
    todo = [t.to_dict() for t in trials if t.key not in done]
    resumed = len(trials) - len(todo)
    with tqdm(
        total=len(trials),
        initial=resumed,
        desc=desc,
        unit="trial",
        file=sys.stderr,
        disable=not progress,
    ) as bar:
        for row in executor.map_unordered(run_trial, todo):
            if store is not None:
                store.append(row)
            done[row["key"]] = row
            if on_row is not None:
                on_row(row)
            bar.update(1)
    return SweepRun([done[t.key] for t in trials], len(todo), resumed)


def result_rows(run: SweepRun) -> list[dict[str, Any]]:
    """The rows' results alone, in manifest order: what must not depend on where or when a
    trial ran (timing and provenance left out by design)."""
    return [row["result"] for row in run.rows]
