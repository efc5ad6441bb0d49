"""`omnisort intrinsics calibrate|export|import`: the camera's OCamCalib model."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

from omnisort_hw.cli.arg_types import Subcommands, output_file
from omnisort_hw.cli.output import print_result, print_verdict
from omnisort_hw.cli.request_flags import add_request_arguments, request_from
from omnisort_hw.pipeline.requests import CalibrateRequest

INTRINSICS = {"what": "intrinsics"}


def register(sub: Subcommands) -> None:
    parser = sub.add_parser("intrinsics", help="calibrate the fisheye camera's intrinsics")
    isub = parser.add_subparsers(dest="intrinsics_command", required=True, metavar="ACTION")

    cal = isub.add_parser("calibrate", help="calibrate from checkerboard images")
    cal.add_argument("images", nargs="+", type=Path, metavar="IMAGE")
    add_request_arguments(cal, CalibrateRequest, fixed=INTRINSICS, skip=("folder",))
    cal.add_argument("--out", type=output_file, required=True, help="camera.json to write")
    cal.add_argument("--json", action="store_true", help="print the result as one JSON object")
    cal.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    cal.set_defaults(func=cmd_calibrate)

    exp = isub.add_parser("export", help="camera.json -> OCamCalib calib_results.txt")
    exp.add_argument("camera", type=Path)
    exp.add_argument("--out", type=output_file, required=True)
    exp.set_defaults(func=cmd_export)

    imp = isub.add_parser("import", help="OCamCalib calib_results.txt -> camera.json")
    imp.add_argument("ocam_txt", type=Path)
    imp.add_argument("--out", type=output_file, required=True)
    imp.set_defaults(func=cmd_import)


def cmd_calibrate(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from omnisort_hw.cli.file_rig import FileRig
    from omnisort_hw.core.intrinsics_report import OUTER_BAND
    from omnisort_hw.pipeline import intrinsics
    from omnisort_hw.pipeline.requests import board_spec
    from omnisort_hw.runlog import RunLog

    calibrate = request_from(
        CalibrateRequest, args, "intrinsics calibrate", fixed=INTRINSICS, skip=("folder",)
    )
    folders = {p.resolve().parent for p in args.images}  # kept in camera.json, as the service
    asked = replace(calibrate, folder=str(folders.pop()) if len(folders) == 1 else None)
    board_spec(asked.board, asked.square_mm, "--board/--square")  # before any image
    request = asked.intrinsics(tuple(args.images))
    with (
        tqdm(
            total=len(request.images),
            desc="detecting boards",
            unit="img",
            file=sys.stderr,
            disable=None,
        ) as bar,
        RunLog(args.log) as log,
    ):
        rig = FileRig(out=args.out, log=log, sort_config=None, registration_config=None)
        done = intrinsics.run(rig, request, on_detected=lambda _n: bar.update(1))
    result, figures, report_path = done.calibration.result, done.calibration.figures, done.report
    summary = done.reply()
    if args.json:
        print_result(summary)
    else:
        model = result.model
        print(f"camera model written to {args.out}")
        print(f"  RMS reprojection error  {result.rms_px:.3f} px, {len(result.images_used)} images")
        print(f"  centre (u, v)           {model.center_uv[0]:.2f}, {model.center_uv[1]:.2f}")
        print(f"  polynomial degree       {result.degree}")
        print(
            f"  field of view           {figures.circle_field_deg:.1f} deg across the image "
            f"circle (r = {figures.circle_radius_px:.0f} px); corners seen out to "
            f"{figures.corners_field_deg:.1f} deg"
        )
        for name, rms in result.per_image_rms_px.items():
            print(f"    {rms:6.3f} px  {name}")
        for rej in result.images_rejected:
            print(f"  rejected {rej.name}: {rej.reason}")
        for cr in result.corners_rejected:
            print(f"  corner {cr.corner} of {cr.name} left out: {cr.reason}")
        print(f"  outer {OUTER_BAND:.0%} of the image circle covered: {figures.outer_coverage:.0%}")
        print(f"  report                  {report_path}")
        print_verdict(summary)
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from omnisort_hw.core.camera_io import export_ocamcalib, load_camera_json

    model, _ = load_camera_json(args.camera)
    export_ocamcalib(args.out, model)
    print(f"OCamCalib calib_results written to {args.out}")
    return 0


def cmd_import(args: argparse.Namespace) -> int:
    from omnisort_hw.core.camera_io import import_ocamcalib, save_camera_json

    model = import_ocamcalib(args.ocam_txt)
    save_camera_json(
        args.out,
        model,
        source=str(args.ocam_txt),
        created=datetime.now(UTC).isoformat(timespec="seconds"),
    )
    print(f"camera model written to {args.out} (fov {model.fov_deg:.1f} deg)")
    return 0
