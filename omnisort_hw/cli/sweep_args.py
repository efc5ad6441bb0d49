"""The options every `omnisort evaluate` experiment shares: where its trials run and where
its rows are kept (docs/sweeps.md)."""

from __future__ import annotations

import argparse
import hashlib
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from omnisort_hw.cli.arg_types import output_folder

DEFAULT_ROOT = Path("build") / "sweeps"


def add_sweep_arguments(p: argparse.ArgumentParser) -> None:
    """--executor, --workers, --scheduler, --sweep-dir, --trial-timeout."""
    p.add_argument(
        "--executor",
        choices=("serial", "pool", "dask"),
        default="pool",
        help="where the trials run: this process, a local process pool (default, one per "
        "core), or a Dask cluster (pip install 'omnisort-hw[dask]')",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="pool or local Dask cluster size (default: the machine's cores)",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="with --executor dask: the cluster's scheduler, tcp://HOST:PORT (default: a "
        "local cluster on 127.0.0.1)",
    )
    p.add_argument(
        "--sweep-dir",
        type=output_folder,
        default=None,
        help="manifest and rows of the sweep; run again to resume it (default: "
        "build/sweeps/EXPERIMENT-HASH, one folder per set of trials)",
    )
    p.add_argument(
        "--trial-timeout",
        type=float,
        default=None,
        metavar="S",
        help="fail when no trial finishes for this long (default: wait)",
    )


def sweep_dir(args: argparse.Namespace, experiment: str, trials: Sequence[Any]) -> Path:
    """--sweep-dir, or a folder named after the trials' keys and the code's git revision:
    the same command on the same code resumes; changed code starts afresh instead of
    reusing rows it did not compute."""
    from omnisort_hw.sweeps.provenance import git_revision

    if args.sweep_dir is not None:
        return Path(args.sweep_dir)
    text = "".join(t.key for t in trials) + (git_revision() or "")
    return DEFAULT_ROOT / f"{experiment}-{hashlib.sha256(text.encode()).hexdigest()[:12]}"


def _warn_other_revision(folder: Path) -> None:
    """A resumed sweep started by other code: say so (its rows carry their revision)."""
    import json

    from omnisort_hw.sweeps.provenance import git_revision

    try:
        made_by = json.loads((folder / "manifest.json").read_text()).get("git")
    except (OSError, ValueError):
        return
    now = git_revision()
    if made_by and now and made_by != now:
        print(
            f"warning: {folder} was started by revision {made_by}, this is {now}; "
            "each row records the revision that computed it",
            file=sys.stderr,
        )


def run_cli_sweep(
    args: argparse.Namespace,
    experiment: str,
    trials: Sequence[Any],
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> tuple[Any, Path]:
    """Run (or resume) the trials on the chosen executor; returns (SweepRun, folder)."""
    from omnisort_hw.sweeps.executors import make_executor
    from omnisort_hw.sweeps.runner import run_sweep

    folder = sweep_dir(args, experiment, trials)
    _warn_other_revision(folder)
    with make_executor(args.executor, args.workers, args.scheduler, args.trial_timeout) as ex:
        print(
            f"{experiment}: {len(trials)} trials on {args.executor} ({ex.workers} workers), "
            f"rows in {folder / 'rows.jsonl'}",
            file=sys.stderr,
        )
        run = run_sweep(
            trials, folder, ex, progress=sys.stderr.isatty(), on_row=on_row, desc=experiment
        )
    if run.resumed:
        print(f"{experiment}: {run.resumed} trials were already done", file=sys.stderr)
    return run, folder
