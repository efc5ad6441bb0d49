"""`omnisort check [IMAGE]` (the drift check, on an image or a capture) and `omnisort evaluate
drift`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from omnisort_hw.cli.arg_types import Subcommands, output_file
from omnisort_hw.cli.output import EXIT_DRIFT, print_result, print_verdict
from omnisort_hw.cli.request_flags import add_request_arguments, request_from
from omnisort_hw.cli.sweep_args import add_sweep_arguments, run_cli_sweep
from omnisort_hw.pipeline.requests import CheckRequest

if TYPE_CHECKING:
    pass


def register(sub: Subcommands) -> None:
    p = sub.add_parser(
        "check", help="drift check: an image against the stored calibration and robot base"
    )
    add_request_arguments(p, CheckRequest)
    p.add_argument("--system", type=Path, required=True, help="system.json with robot_base")
    p.add_argument(
        "--reference",
        type=Path,
        default=None,
        help="the image the robot was registered with (default: drift_reference.png beside "
        "system.json when it belongs to it; otherwise the board alone)",
    )
    p.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell file: [registration], [watchdog]; without an image, capture with its camera",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd")
    p.set_defaults(func=cmd_check)


def add_drift_evaluation(esub: Subcommands) -> None:
    """`omnisort evaluate drift` (called by the `evaluate` command group)."""
    ev = esub.add_parser("drift", help="drift watchdog on simulated scenes: alarms and bumps")
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument("--scenes", type=int, default=2, help="random scenes (default 2)")
    ev.add_argument("--unmoved", type=int, default=200, help="captures with the camera unmoved")
    ev.add_argument("--width", type=int, default=960, help="render size (default 960)")
    ev.add_argument("--out", type=output_file, default=None, help="also write the result JSON here")
    ev.add_argument("--json", action="store_true", help="print one JSON object")
    add_sweep_arguments(ev)
    ev.set_defaults(func=cmd_evaluate_drift)


def cmd_check(args: argparse.Namespace) -> int:
    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.pipeline import drift_check
    from omnisort_hw.runlog import RunLog

    request = request_from(CheckRequest, args, "check")
    with RunLog(args.log) as log:
        rig = FileRig(
            config=args.config,
            system=args.system,
            reference=args.reference,
            log=log,
        )
        res = drift_check.run(rig, request)
    s = res.reply()
    if args.json:
        print_result(s)
    else:
        b = s.board
        print(
            f"{'DRIFT' if s.drift else 'ok'}: camera turned {s.angle_deg:.4f} deg "
            f"(rotation vector {s.rotvec_deg} deg in S, threshold {s.threshold_deg:.4f} "
            f"deg, from the {s.source})"
        )
        if b is not None:
            print(
                f"  board: {b.visible}/{b.corners} corners visible, residual median "
                f"{b.residual_px_median} px, max {b.residual_px_max} px; base shift "
                f"{b.base_shift_mm} mm"
            )
        print_verdict(s)
    return EXIT_DRIFT if res.drift else 0


def cmd_evaluate_drift(args: argparse.Namespace) -> int:
    import time

    from omnisort_hw import fileio
    from omnisort_hw.evaluation.drift import drift_trials, summarize_drift

    trials = drift_trials(args.seed, args.scenes, args.unmoved, args.width)
    t0 = time.perf_counter()
    run, _ = run_cli_sweep(args, "drift", trials)
    result = summarize_drift(
        [row["result"] for row in run.rows],
        args.seed,
        args.width,
        args.scenes,
        time.perf_counter() - t0,
    )
    if args.out is not None:
        fileio.atomic_write_json(args.out, result, keep_history=False)
    if args.json:
        print_result(result)
        return 0
    print(
        f"unmoved: {result['unmoved_captures']} captures ({result['occluded_captures']} with the "
        f"board partly hidden), {result['false_alarms']} false alarms, largest angle "
        f"{result['max_unmoved_angle_deg']} deg; threshold median {result['threshold_deg_median']}"
        f" deg"
    )
    for size, row in result["bumps"].items():
        print(
            f"bump {size:>4} deg: {row['detected']}/{row['captures']} detected, angle error "
            f"<= {row['max_angle_error_deg']} deg"
        )
    return 0
