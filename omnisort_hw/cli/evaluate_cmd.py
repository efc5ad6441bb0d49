"""`omnisort evaluate table3`: the paper's comparison on simulated data (and other experiments)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from omnisort_hw.cli import drift_cmd, lighting_cmd, robot_cmd
from omnisort_hw.cli.output import print_result
from omnisort_hw.cli.sweep_args import add_sweep_arguments, run_cli_sweep


def register(sub: Any) -> None:
    ev = sub.add_parser("evaluate", help="reproduce the published experiments on the simulator")
    esub = ev.add_subparsers(dest="evaluate_command", required=True, metavar="EXPERIMENT")
    t3 = esub.add_parser("table3", help="camera/laser calibration: all four methods vs truth")
    t3.add_argument("--n", type=int, default=35, help="configurations (default 35)")
    t3.add_argument("--seed", type=int, default=0)
    t3.add_argument("--degraded", action="store_true", help="'real camera' degradation mode")
    t3.add_argument("--width", type=int, default=None, help="render size (default 1920)")
    t3.add_argument(
        "--data",
        type=Path,
        default=None,
        help="dataset folder: read it if it holds this experiment, else render into it (then "
        "the images are kept and calibrated in this process; without it each trial renders "
        "its configuration on its worker)",
    )
    t3.add_argument(
        "--tone-curve",
        default="srgb",
        help="the simulated camera's tone curve when rendering: srgb (default) or linear",
    )
    t3.add_argument(
        "--assume-tone-curve",
        default=None,
        help="the curve the extraction assumes (default: the dataset's own); 'linear' is what "
        "the extraction assumed before it modelled tone curves",
    )
    t3.add_argument(
        "--frames",
        type=int,
        default=1,
        help="with --degraded: N > 1 measures every target with captures of N laser-on and N "
        "laser-off frames, uncompressed (default 1: one rendered frame, as before)",
    )
    t3.add_argument("--json", action="store_true", help="print one JSON object")
    add_sweep_arguments(t3)
    t3.set_defaults(func=cmd_table3)
    for extension in EXTENSIONS:
        extension(esub)


# Other experiments register here: each adds its own parser to the `evaluate` group.
EXTENSIONS: list[Any] = [
    robot_cmd.add_sorting_evaluation,
    drift_cmd.add_drift_evaluation,
    lighting_cmd.add_lighting_evaluation,
]


def _matching(data: Path, n: int, seed: int, degraded: bool, tone_curve: str) -> bool:
    index = data / "dataset.json"
    if not index.is_file():
        return False
    info = json.loads(index.read_text())
    got = (info.get("n"), info.get("seed"), bool(info.get("degraded")))
    return got == (n, seed, degraded) and info.get("tone_curve", "linear") == tone_curve


def cmd_table3(args: argparse.Namespace) -> int:
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.errors import InputError
    from omnisort_hw.evaluation.table3 import format_table

    if args.n < 1:
        raise InputError(f"--n must be at least 1, got {args.n}")
    if args.frames > 1:
        return lighting_cmd.table3_with_captures(args)
    assume = ToneCurve.parse(args.assume_tone_curve) if args.assume_tone_curve else None
    ToneCurve.parse(args.tone_curve)  # a bad name fails here, not on every worker
    if args.data is None:
        from omnisort_hw.evaluation.table3_trials import summarize_rows, table3_trials

        trials = table3_trials(
            args.n, args.seed, args.width, args.degraded, args.tone_curve, args.assume_tone_curve
        )
        run, folder = run_cli_sweep(args, "table3", trials)
        result = summarize_rows(run.rows, str(folder))
    else:
        result = _evaluate_data(args, assume)
    if args.json:
        print_result(result)
    else:
        print(format_table(result))
    return 0


def _evaluate_data(args: argparse.Namespace, assume: Any) -> dict[str, Any]:
    """--data: the dataset on disk (rendered into it first when it is not this one)."""
    from omnisort_hw.evaluation.table3 import evaluate_dataset

    data = args.data
    if not _matching(data, args.n, args.seed, args.degraded, args.tone_curve):
        from sim_backend.dataset import make_dataset

        print(f"rendering {args.n} configurations into {data}", file=sys.stderr)
        make_dataset(
            data,
            "table3",
            args.n,
            args.seed,
            width=args.width,
            degraded=args.degraded,
            progress=sys.stderr.isatty() or not args.json,
            tone_curve=args.tone_curve,
        )
    return evaluate_dataset(data, progress=sys.stderr.isatty(), tone=assume)
