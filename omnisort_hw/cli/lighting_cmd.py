"""`omnisort evaluate lighting`: single frames against measurement captures under hostile light."""

from __future__ import annotations

import argparse
import sys

from omnisort_hw.cli.arg_types import Subcommands
from omnisort_hw.cli.output import print_result
from omnisort_hw.cli.sweep_args import add_sweep_arguments, run_cli_sweep


def add_lighting_evaluation(esub: Subcommands) -> None:
    """Register `evaluate lighting` in the `evaluate` group."""
    p = esub.add_parser(
        "lighting",
        help="hostile light (sunlight, red objects, specular floor, saturated stripe, flicker): "
        "single frame vs measurement capture",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--frames", type=int, default=8, help="laser-on and laser-off frames each")
    p.add_argument("--width", type=int, default=1280, help="camera size in px (square)")
    p.add_argument(
        "--scenario", action="append", default=None, help="only this scenario (repeatable)"
    )
    p.add_argument(
        "--no-calibration",
        action="store_true",
        help="leave out the calibrations from each acquisition (the map's figures only)",
    )
    p.add_argument(
        "--effects",
        action="store_true",
        help="through a colour camera's effects as well (crosstalk, chromatic aberration, "
        "bloom, Bayer demosaicing), as a real camera sees",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_sweep_arguments(p)
    p.set_defaults(func=cmd_lighting)


def cmd_lighting(args: argparse.Namespace) -> int:
    from omnisort_hw.errors import InputError
    from omnisort_hw.evaluation.lighting import (
        SCENARIOS,
        format_lighting,
        lighting_trials,
        summarize_lighting,
    )

    chosen = tuple(args.scenario or SCENARIOS)
    unknown = [s for s in chosen if s not in SCENARIOS]
    if unknown:
        raise InputError(f"--scenario {unknown[0]!r}: known are {', '.join(SCENARIOS)}")
    if not 1 <= args.frames <= 64:
        raise InputError(f"--frames must be 1..64, got {args.frames}")
    if args.width < 64:
        raise InputError(f"--width must be at least 64, got {args.width}")
    trials = lighting_trials(
        args.seed,
        args.frames,
        args.width,
        chosen,
        calibrate=not args.no_calibration,
        effects=args.effects,
    )
    run, _ = run_cli_sweep(args, "lighting", trials)
    result = summarize_lighting(run.rows, args.seed, args.frames, args.width, args.effects)
    if args.json:
        print_result(result)
    else:
        print(format_lighting(result))
    return 0


def table3_with_captures(args: argparse.Namespace) -> int:
    """`evaluate table3 --degraded --frames N` (N > 1): Table 3 measured with captures."""
    from omnisort_hw.errors import InputError
    from omnisort_hw.evaluation.table3 import format_table
    from omnisort_hw.evaluation.table3_capture import evaluate_captures

    if not args.degraded:
        raise InputError("--frames N > 1 measures the degraded camera: add --degraded")
    if args.frames > 64:
        raise InputError(f"--frames must be 1..64, got {args.frames}")
    result = evaluate_captures(
        args.n, args.seed, args.frames, args.width, progress=sys.stderr.isatty()
    )
    if args.json:
        print_result(result)
    else:
        print(format_table(result))
    return 0
