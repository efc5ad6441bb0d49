"""`omnisort extrinsics calibrate` and `omnisort map`: the camera-laser system from one image."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

from omnisort_hw.cli.arg_types import Subcommands, output_file
from omnisort_hw.cli.output import print_result, print_verdict
from omnisort_hw.cli.request_flags import add_request_arguments, request_from
from omnisort_hw.core.records import PictureReply
from omnisort_hw.pipeline.requests import CalibrateRequest, MapRequest

EXTRINSICS = {"what": "extrinsics"}


def register(sub: Subcommands) -> None:
    ext = sub.add_parser("extrinsics", help="calibrate camera rotation and laser plane")
    esub = ext.add_subparsers(dest="extrinsics_command", required=True, metavar="ACTION")
    cal = esub.add_parser("calibrate", help="from one image of a calibration target")
    add_request_arguments(cal, CalibrateRequest, fixed=EXTRINSICS)
    cal.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell.toml: without an image, measure the target with its camera and laser (a "
        "capture: averaged board frames for the edges, on/off pairs for the stripe); its "
        "[target] gives the defaults of --target and --separation",
    )
    cal.add_argument("--camera", type=Path, required=True, help="camera.json (intrinsics)")
    cal.add_argument(
        "--tone-curve",
        default=None,
        help="the camera's tone curve: srgb, linear, gamma:G, or a JSON table of 256 light "
        "values (measured); default: the --config camera's, else srgb (8-bit cameras)",
    )
    cal.add_argument(
        "--out",
        type=output_file,
        required=True,
        help="system.json to write (and beside it STEM_overlay.png: what was detected and fitted)",
    )
    cal.add_argument("--json", action="store_true", help="print the result as one JSON object")
    cal.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    cal.set_defaults(func=cmd_calibrate)

    mp = sub.add_parser("map", help="laser pixels -> points on the laser plane (mm)")
    add_request_arguments(mp, MapRequest, defaults={"picture": True})
    mp.add_argument("--system", type=Path, required=True, help="system.json")
    mp.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell.toml: without an image, measure with its camera and laser (a capture)",
    )
    mp.add_argument("--json", action="store_true")
    mp.add_argument(
        "--png",
        type=output_file,
        default=None,
        help="where the map's picture goes; default: IMAGE-STEM_map_overlay.png beside "
        "--system (capture_map_overlay.png)",
    )
    mp.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    mp.set_defaults(func=cmd_map)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.pipeline import extrinsics
    from omnisort_hw.runlog import RunLog

    request = request_from(CalibrateRequest, args, "extrinsics calibrate", fixed=EXTRINSICS)
    with RunLog(args.log) as log:
        rig = FileRig(
            config=args.config,
            camera=args.camera,
            out=args.out,
            tone=ToneCurve.parse(args.tone_curve) if args.tone_curve else None,
            log=log,
        )
        result = extrinsics.run(rig, request).reply()
    _warn(result)
    if args.json:
        print_result(result)
    else:
        print(f"system calibration ({result.method}) written to {args.out}")
        for key, value in result.parameters.items():
            std = result.std.get(key)
            extra = f"  +- {std:.4f}" if std is not None else ""
            print(f"  {key:<20} {value:10.4f}{extra}")
        print_verdict(result)
    return 0


def _warn(picture: PictureReply) -> None:
    """A picture that could not be written: said on stderr, the command still succeeds."""
    if picture.overlay_problem:
        print(f"omnisort: warning: {picture.overlay_problem}", file=sys.stderr)


def cmd_map(args: argparse.Namespace) -> int:
    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.pipeline import laser_map
    from omnisort_hw.runlog import RunLog

    request = request_from(MapRequest, args, "map")
    if args.png is not None:
        request = replace(request, picture=True)
    with RunLog(args.log) as log:
        rig = FileRig(config=args.config, system=args.system, png=args.png, log=log)
        result = laser_map.run(rig, request)
    _warn(result.picture)
    if args.json:
        print_result(result.reply())
    else:
        segs = result.laser_map.segments
        print(f"{len(result.laser_map.pixels)} laser points, {len(segs)} segments")
        for i, s in enumerate(segs):
            print(
                f"  segment {i}: {len(s.points_S):5d} points  distance {s.distance_mm:8.1f} mm"
                f"  bearing {s.bearing_deg:7.1f} deg  length {s.length_mm:7.1f} mm"
            )
        print_verdict(result.reply())
    return 0
