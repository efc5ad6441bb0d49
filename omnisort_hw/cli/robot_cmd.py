"""`omnisort register-robot`, `locate`, `sort` and `evaluate sorting`: the robot side of the cell.

    omnisort register-robot IMAGE --system system.json --board 9x6 --square 40 \\
        --offset 200,-180,2,180,0,90
    omnisort register-robot --config cell.toml --system system.json   # capture, [registration]
    omnisort locate IMAGE --system system.json [--config cell.toml] [--laser-image IMAGE]
    omnisort locate --config cell.toml --system system.json          # capture
    omnisort sort --config cell.toml [--system system.json] [--register] [--json]
    omnisort evaluate sorting --scenes 50 --seed 0 [--json]

`--offset X,Y,Z,RX,RY,RZ` is the floor board's pose in the robot base frame B (mm, degrees,
R = Rz(RZ) Ry(RY) Rx(RX)); the board frame has its origin at the first inner corner, x along
the first row of corners, y towards the next row, z into the printed face (so a board lying
face up has RX = 180). See `omnisort_hw.core.registration`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from omnisort_hw.cli.arg_types import Subcommands, output_file
from omnisort_hw.cli.cell_file import load_cell
from omnisort_hw.cli.output import print_result, print_verdict
from omnisort_hw.cli.request_flags import add_request_arguments, request_from
from omnisort_hw.cli.sweep_args import add_sweep_arguments, run_cli_sweep
from omnisort_hw.config.location_settings import LOCATION_KEYS, LocationSettings, location_changes
from omnisort_hw.config.registration_settings import RegistrationSettings
from omnisort_hw.errors import ConfigError, InputError
from omnisort_hw.pipeline.replies import SortReply
from omnisort_hw.pipeline.requests import LocateRequest, RegisterRequest, SortRequest
from omnisort_hw.request_fields import args_of


def register(sub: Subcommands) -> None:
    reg = sub.add_parser(
        "register-robot", help="robot base pose T_SB from the floor checkerboard in one image"
    )
    add_request_arguments(reg, RegisterRequest)
    reg.add_argument(
        "--system", type=Path, required=True, help="system.json (read, robot_base written)"
    )
    reg.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell.toml: without an image, capture with its camera (laser off); its "
        "[registration] gives what the flags below do not",
    )
    add_request_arguments(reg, RegistrationSettings)
    reg.add_argument("--json", action="store_true", help="print the result as one JSON object")
    reg.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    reg.set_defaults(func=cmd_register)

    loc = sub.add_parser("locate", help="find the cubes: colour, centre and yaw in S and B")
    add_request_arguments(loc, LocateRequest)
    loc.add_argument("--system", type=Path, required=True, help="system.json with robot_base")
    loc.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell.toml: locate with its [sorting] section, as the service does; without an "
        "image, capture with its camera and laser",
    )
    add_request_arguments(loc, LocationSettings)  # over --config's [sorting]
    loc.add_argument("--json", action="store_true")
    loc.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    loc.set_defaults(func=cmd_locate)

    srt = sub.add_parser("sort", help="locate the cubes and put each in the bin of its colour")
    srt.add_argument("--config", type=Path, required=True, help="cell.toml")
    srt.add_argument(
        "--system",
        type=Path,
        default=None,
        help="system.json (default: the calibration store of the config's [storage])",
    )
    add_request_arguments(srt, SortRequest)
    srt.add_argument("--json", action="store_true")
    srt.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    srt.set_defaults(func=cmd_sort)


def add_sorting_evaluation(esub: Subcommands) -> None:
    """`omnisort evaluate sorting` (called by the `evaluate` command group)."""
    ev = esub.add_parser(
        "sorting", help="random scenes on the simulated cell: register, locate, sort, verify"
    )
    ev.add_argument("--scenes", type=int, default=50, help="number of random scenes")
    ev.add_argument("--seed", type=int, default=0)
    ev.add_argument("--width", type=int, default=960, help="render size (default 960)")
    ev.add_argument(
        "--calibration",
        choices=("truth", "perturbed"),
        default="truth",
        help="true camera/laser calibration, or one with the joint method's typical errors",
    )
    ev.add_argument("--max-angle", type=float, default=10.0, help="camera angles, +-deg")
    ev.add_argument(
        "--effects",
        action="store_true",
        help="each scene through a real colour camera (noise, blur, JPEG, crosstalk, chromatic "
        "aberration, bloom, Bayer demosaicing), not as clean renders",
    )
    ev.add_argument("--out", type=output_file, default=None, help="also write the result JSON here")
    ev.add_argument("--json", action="store_true", help="print one JSON object")
    add_sweep_arguments(ev)
    ev.set_defaults(func=cmd_evaluate_sorting)


def _registration(args: argparse.Namespace) -> Any:
    """The registration settings (`RegistrationConfig`): the flags over `[registration]` of
    --config (or, without one, the flags alone), checked as the cell file's section is."""
    from omnisort_hw.config.sorting import registration_config

    base = None
    if args.config is not None:
        cell, _ = load_cell(args.config, devices=False)
        base = cell.registration
    values = base.settings() if base is not None else {}
    flags = {a.name: a.cli_flag for a in args_of(RegistrationSettings)}
    values |= {name: getattr(args, name) for name in flags if getattr(args, name) is not None}
    hint = "" if base is not None else " (or a [registration] section in --config)"
    return registration_config(
        values, "register-robot", lambda a: flags[a.name], InputError, missing_hint=hint
    )


def cmd_register(args: argparse.Namespace) -> int:
    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.pipeline import registration
    from omnisort_hw.runlog import RunLog

    request = request_from(RegisterRequest, args, "register-robot")
    with RunLog(args.log) as log:
        rig = FileRig(
            config=args.config,
            system=args.system,
            log=log,
            sort_config=None,
            registration_config=_registration(args),
        )
        result = registration.run(rig, request)
    reply = result.reply()
    if args.json:
        print_result(reply)
        return 0
    print("\n".join(result.lines(with_verdict=False)))
    print(f"written to {result.path}" if result.path else "not written (--no-save)")
    print_verdict(reply)
    return 0


def _locate_config(resolved: Any, args: argparse.Namespace) -> Any:
    """The `[sorting]` record of `--config` as the rig resolved it (what the service locates
    with), else the defaults; the flags of `LocationSettings` override it, checked as the
    cell file's keys are."""
    from dataclasses import replace

    from omnisort_hw.core.pick_planning import SortConfig

    if args.config is not None and resolved is None:
        raise ConfigError(f"{args.config}: no [sorting] section")
    cfg = resolved if resolved is not None else SortConfig()
    given = {name: getattr(args, name) for name in LOCATION_KEYS}
    return replace(cfg, **location_changes(given, lambda a: a.cli_flag, InputError))


def cmd_locate(args: argparse.Namespace) -> int:
    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.pipeline import locate
    from omnisort_hw.runlog import RunLog

    request = request_from(LocateRequest, args, "locate")
    with RunLog(args.log) as log:
        rig = FileRig(config=args.config, system=args.system, log=log, registration_config=None)
        rig.sort_config = _locate_config(rig.sort_config, args)
        result = locate.run(rig, request)
    reply = result.reply()
    if args.json:
        print_result(reply)
        return 0
    cubes = result.asked()
    print(f"{len(cubes)} cubes")
    for i, c in enumerate(cubes):
        s, b = c.center_S, c.center_B
        print(
            f"  {i}: {c.color:<8} S ({s[0]:8.1f}, {s[1]:8.1f}, {s[2]:8.1f})  "
            f"B ({b[0]:8.1f}, {b[1]:8.1f}, {b[2]:8.1f}) mm  yaw {c.yaw_B_deg:6.1f} deg (B)  "
            f"+- {c.sigma_mm:.2f} mm" + (f"  [{'; '.join(c.notes)}]" if c.notes else "")
        )
    print_verdict(reply)
    return 0


def cmd_sort(args: argparse.Namespace) -> int:
    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.pipeline import sort_run
    from omnisort_hw.runlog import RunLog

    request = request_from(SortRequest, args, "sort")
    with RunLog(args.log) as log:
        rig = FileRig(config=args.config, system=args.system, log=log)
        progress = None if args.json else _print_progress
        report = sort_run.run(rig, request, progress=progress)
    _print_report(report.reply(), args.json)
    return 0


def _print_progress(event: dict[str, Any]) -> None:
    """The sorter's events on stderr: the planned total once, then each cube's outcome."""
    if "to_pick" in event:
        print(f"  {event['located']} cubes located, {event['to_pick']} to pick", file=sys.stderr)
        return
    print(f"  cube {event['cube']} ({event['color']}): {event['status']}", file=sys.stderr)


def _print_report(result: SortReply, as_json: bool) -> None:
    if as_json:
        print_result(result)
        return
    for c in result.cubes:
        err = f"  error {c.error_mm:.2f} mm" if c.error_mm is not None else ""
        ok = ""
        if c.in_right_bin is not None:
            ok = "  in its bin" if c.in_right_bin else "  NOT in its bin"
        where = c.center_B_mm
        print(
            f"cube {c.index}: {c.color:<8} {c.status:<8} B ({where[0]:.1f}, "
            f"{where[1]:.1f}, {where[2]:.1f}) mm{err}{ok}" + (f"  - {c.reason}" if c.reason else "")
        )
    t = result.totals
    print(
        f"totals: {t.cubes} cubes, {t.sorted} sorted, {t.skipped} skipped, "
        f"{t.failed} failed; planned motion {t.planned_motion_s:.1f} s; "
        f"wall {t.wall_s:.1f} s"
        + (
            f"; verified: {t.sorted_ok} in the right bin, {t.collisions} collisions, "
            f"mean position error {t.mean_position_error_mm} mm"
            if t.sorted_ok is not None
            else ""
        )
    )
    print_verdict(result)


def cmd_evaluate_sorting(args: argparse.Namespace) -> int:
    import time

    from omnisort_hw.evaluation.sorting import SUMMARY_KEYS, sorting_trials, summarize_rows
    from omnisort_hw.fileio import atomic_write_json

    if args.scenes < 1:
        raise InputError(f"--scenes must be at least 1, got {args.scenes}")

    def progress(row: dict[str, Any]) -> None:
        if args.json:
            return
        res = row["result"]
        state = res.get("error") or f"{res['sorted_ok']}/{res['cubes']} sorted"
        print(f"  scene {res['scene'] + 1}/{args.scenes}: {state}", file=sys.stderr, flush=True)

    trials = sorting_trials(
        args.scenes, args.seed, args.width, args.calibration, args.max_angle, effects=args.effects
    )
    t0 = time.perf_counter()
    run, _ = run_cli_sweep(args, "sorting", trials, on_row=progress)
    result = summarize_rows(run.rows, time.perf_counter() - t0)
    if args.out is not None:
        atomic_write_json(args.out, result, keep_history=False)
    if args.json:
        print_result(result)
        return 0
    for k in (*SUMMARY_KEYS, "wall_s"):
        print(f"{k:<28} {result[k]}")
    for item in result["not_sorted"]:
        print(f"  scene {item['scene']}: {item['error'] or '; '.join(item['reasons'])}")
    return 0
