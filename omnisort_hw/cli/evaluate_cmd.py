"""`omnisort evaluate table3`: the paper's comparison on simulated data (and other experiments)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omnisort_hw.cli import drift_cmd, lighting_cmd, robot_cmd
from omnisort_hw.cli.arg_types import Subcommands
from omnisort_hw.cli.output import print_result
from omnisort_hw.cli.sweep_args import add_sweep_arguments, run_cli_sweep

if TYPE_CHECKING:  # imported by the command that uses it: --help stays quick
    from omnisort_hw.core.radiometry import ToneCurve


def register(sub: Subcommands) -> None:
    ev = sub.add_parser("evaluate", help="reproduce the published experiments on the simulator")
    esub = ev.add_subparsers(dest="evaluate_command", required=True, metavar="EXPERIMENT")
    t3 = esub.add_parser("table3", help="camera/laser calibration: all four methods vs truth")
    # Left out, these take --data's own values (or the defaults below): a dataset is never
    # rendered over with other parameters.
    t3.add_argument("--n", type=int, default=None, help="configurations (default 35)")
    t3.add_argument("--seed", type=int, default=None, help="(default 0)")
    t3.add_argument(
        "--degraded", action="store_true", default=None, help="'real camera' degradation mode"
    )
    t3.add_argument("--width", type=int, default=None, help="render size (default 1920)")
    t3.add_argument(
        "--data",
        type=Path,
        default=None,
        help="dataset folder: read it with its own parameters when it holds a dataset (one "
        "given that differs is refused, naming it), else render into it (then the images are "
        "kept and calibrated in this process; without it each trial renders its "
        "configuration on its worker)",
    )
    t3.add_argument(
        "--tone-curve",
        default=None,
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
EXTENSIONS: list[Callable[[Subcommands], None]] = [
    robot_cmd.add_sorting_evaluation,
    drift_cmd.add_drift_evaluation,
    lighting_cmd.add_lighting_evaluation,
]


TABLE3_DEFAULTS = {"n": 35, "seed": 0, "degraded": False, "tone_curve": "srgb"}
"""What `evaluate table3` renders when a parameter is left out and no dataset gives it."""


def _dataset_parameters(args: argparse.Namespace) -> None:
    """Fill the parameters left out: from --data's dataset when it holds one (a given one
    that differs is refused, naming each), else the defaults. An older index without a tone
    curve was rendered linear."""
    from omnisort_hw.errors import InputError

    given = {
        key: getattr(args, key)
        for key in ("n", "seed", "degraded", "tone_curve", "width")
        if getattr(args, key) is not None
    }
    info = None
    if args.data is not None:
        from sim_backend.dataset import dataset_index, parameter_differences

        info = dataset_index(args.data)
    if info is not None:
        info = {"tone_curve": "linear", **info}
        info["degraded"] = bool(info.get("degraded"))
        differences = parameter_differences(info, given)
        if differences:
            raise InputError(
                f"--data {args.data} holds another dataset ({', '.join(differences)}); it is "
                "not rendered over: leave those options out to evaluate it, or give another "
                "folder"
            )
        for key in TABLE3_DEFAULTS:
            setattr(args, key, info.get(key, TABLE3_DEFAULTS[key]))
        return
    for key, value in TABLE3_DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, value)


def cmd_table3(args: argparse.Namespace) -> int:
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.errors import InputError
    from omnisort_hw.evaluation.table3 import format_table

    _dataset_parameters(args)
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


def _evaluate_data(args: argparse.Namespace, assume: ToneCurve | None) -> dict[str, Any]:
    """--data: the dataset on disk (rendered into it first when it holds none)."""
    from omnisort_hw.evaluation.table3 import evaluate_dataset
    from sim_backend.dataset import dataset_index

    data = args.data
    if dataset_index(data) is None:
        from omnisort_hw.errors import InputError
        from sim_backend.dataset import dataset_problem, make_dataset

        problem = dataset_problem(data, {})
        if problem:
            raise InputError(f"--data: {problem}")
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
