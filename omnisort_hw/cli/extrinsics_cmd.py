"""`omnisort extrinsics calibrate` and `omnisort map`: the camera-laser system from one image."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from omnisort_hw.cli.arg_types import output_file
from omnisort_hw.cli.output import print_result
from omnisort_hw.errors import InputError


def register(sub: Any) -> None:
    ext = sub.add_parser("extrinsics", help="calibrate camera rotation and laser plane")
    esub = ext.add_subparsers(dest="extrinsics_command", required=True, metavar="ACTION")
    cal = esub.add_parser("calibrate", help="from one image of a calibration target")
    cal.add_argument("image", type=Path, nargs="?", default=None)
    cal.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell.toml: without an image, measure the target with its camera and laser (a "
        "capture: averaged board frames for the edges, on/off pairs for the stripe)",
    )
    cal.add_argument("--camera", type=Path, required=True, help="camera.json (intrinsics)")
    cal.add_argument(
        "--target", required=True, choices=("two-sided", "three-sided", "checkerboards")
    )
    cal.add_argument(
        "--separation",
        type=float,
        default=None,
        help="measured inner distance between the walls, mm (required for the wall targets, "
        "or [target] separation_mm of --config)",
    )
    cal.add_argument(
        "--target-file",
        type=Path,
        default=None,
        help="target description TOML (deploy/target.example.toml): the wall target as "
        "measured, separation and markers; default: the symmetric paper target",
    )
    cal.add_argument("--board", default="9x6", help="inner corners COLSxROWS (checkerboards)")
    cal.add_argument("--square", type=float, default=97.0, help="square size mm (checkerboards)")
    cal.add_argument(
        "--method",
        choices=("joint", "paper", "method1", "method2"),
        default=None,
        help="default: the best one for the target",
    )
    cal.add_argument(
        "--tone-curve",
        default="srgb",
        help="the camera's tone curve: srgb (default, 8-bit cameras), linear, gamma:G, or a "
        "JSON table of 256 light values (measured)",
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
    mp.add_argument("image", type=Path, nargs="?", default=None)
    mp.add_argument("--system", type=Path, required=True, help="system.json")
    mp.add_argument(
        "--config",
        type=Path,
        default=None,
        help="cell.toml: without an image, measure with its camera and laser (a capture)",
    )
    mp.add_argument("--json", action="store_true")
    mp.add_argument(
        "--points",
        action="store_true",
        help="with --json: every laser point in S (mm) and its pixel (points_S, pixels)",
    )
    mp.add_argument(
        "--png",
        type=output_file,
        default=None,
        help="the map's picture (image with its laser points, and their top view in mm); "
        "default: IMAGE-STEM_map_overlay.png beside --system (capture_map_overlay.png)",
    )
    mp.add_argument("--log", type=output_file, default=None, help="write a rerun .rrd of the run")
    mp.set_defaults(func=cmd_map)


def _floor(calib: Any, config: Path | None) -> Any:
    """The floor the map's mirror images are judged against, as the service has it: from the
    registered robot base and the cell file's `[sorting]`, or None without a registration."""
    from omnisort_hw.cli.cell_file import sorting_config
    from omnisort_hw.pipeline.laser_map import floor_plane_S

    return floor_plane_S(calib, sorting_config(config) if config is not None else None)


def measure(config: Path | None, log: Any, board: bool) -> Any:
    """A measurement capture with the cell file's camera and laser (`MeasurementCapture`)."""
    from omnisort_hw.cell.devices import open_devices
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.pipeline.measurement_capture import capture_measurement

    if config is None:
        raise InputError("give an image, or --config CELL.toml to measure with the cell")
    cell = load_cell_config(config)
    devices = open_devices(cell.devices)
    if devices.camera is None or devices.laser is None:
        raise InputError(f"{config}: a capture needs the [camera] and [laser] sections")
    with devices.camera as cam, devices.laser as laser:
        return capture_measurement(cam, laser, cell.capture, log, board=board)


def laser_off_frame(config: Path | None) -> Any:
    """One frame of the cell file's camera with its laser switched off (registration, colours)."""
    from omnisort_hw.cell.devices import open_devices
    from omnisort_hw.config.cell import load_cell_config

    if config is None:
        raise InputError("give an image, or --config CELL.toml to capture with the cell")
    devices = open_devices(load_cell_config(config).devices)
    if devices.camera is None:
        raise InputError(f"{config}: a capture needs the [camera] section")
    with devices.camera as cam:
        if devices.laser is None:
            return cam.grab().image
        with devices.laser as laser:
            laser.set(False)
            return cam.grab().image


def load_system(path: Path) -> Any:
    """system.json from the CLI or from the service's store (then its checksum is verified)."""
    from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
    from omnisort_hw.pipeline.calibration_source import read_system_payload

    payload, _ = read_system_payload(path)
    return SystemCalibration.from_json(payload, source=str(path))


def cmd_calibrate(args: argparse.Namespace) -> int:
    from omnisort_hw.core.camera_io import load_camera_json
    from omnisort_hw.core.overlays import overlay_path, write_picture
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.fileio import atomic_write_json
    from omnisort_hw.pipeline.extrinsics import (
        calibration_result,
        image_record,
        resolve_target,
        run_extrinsics,
        system_payload,
    )
    from omnisort_hw.pipeline.image_files import read_image
    from omnisort_hw.runlog import RunLog

    default, field = None, "--separation"
    layout = None
    if args.target_file is not None:
        from omnisort_hw.config.target import load_target_description

        layout = load_target_description(args.target_file)
        default, field = layout.separation_mm, f"separation_mm of {args.target_file}"
    elif args.separation is None and args.config is not None and args.target != "checkerboards":
        from omnisort_hw.config.cell import load_cell_config

        default = load_cell_config(args.config).target.separation_mm
        field = f"--separation (or [target] separation_mm in {args.config})"
    _, separation = resolve_target(args.target, args.separation, None, default, field)
    try:
        cols, rows = (int(v) for v in args.board.lower().split("x"))
    except ValueError as exc:
        raise InputError(f"--board must look like 9x6, got {args.board!r}") from exc
    tone = ToneCurve.parse(args.tone_curve)
    model, _ = load_camera_json(args.camera)
    with RunLog(args.log) as log:
        stripe_px = None
        if args.image is not None:
            image, source, record = read_image(args.image), str(args.image), None
        else:
            cap = measure(args.config, log, board=True)
            image, source, record = cap.board_image, "capture", {"capture": cap.record}
            stripe_px, tone = cap.stripe_px, cap.tone or tone
        run = run_extrinsics(
            image,
            model,
            args.target,
            args.method,
            separation_mm=separation,
            board=(cols, rows),
            square_mm=args.square,
            source=source,
            log=log,
            tone=tone,
            stripe_px=stripe_px,
            layout=layout,
        )
    calib = run.calib
    image_rec = image_record(args.image) if args.image is not None else record
    atomic_write_json(args.out, system_payload(calib, image_rec))
    picture = write_picture(overlay_path(args.out), lambda: run.overlay(image, source))
    _warn(picture)
    if args.json:
        print_result(calibration_result(calib, args.target, args.out, picture, image_rec, tone))
    else:
        print(f"system calibration ({calib.method}) written to {args.out}")
        for key, value in calib.parameters().items():
            std = calib.std.get(key)
            extra = f"  +- {std:.4f}" if std is not None else ""
            print(f"  {key:<20} {value:10.4f}{extra}")
        if picture["overlay_png"]:
            print(f"picture of what was detected and fitted: {picture['overlay_png']}")
    return 0


def _warn(picture: dict[str, str | None]) -> None:
    """A picture that could not be written: said on stderr, the command still succeeds."""
    if picture.get("overlay_problem"):
        print(f"omnisort: warning: {picture['overlay_problem']}", file=sys.stderr)


def map_png_path(args: argparse.Namespace) -> Path:
    """The map picture's path: --png, else named after the image, beside system.json."""
    if args.png is not None:
        return Path(args.png)
    stem = args.image.stem if args.image is not None else "capture"
    return args.system.with_name(f"{stem}_map_overlay.png")


def cmd_map(args: argparse.Namespace) -> int:
    from omnisort_hw.core.overlays import write_picture
    from omnisort_hw.pipeline.image_files import read_image
    from omnisort_hw.pipeline.laser_map import map_laser, map_overlay
    from omnisort_hw.runlog import RunLog

    calib = load_system(args.system)
    record, light = None, False
    with RunLog(args.log) as log:
        if args.image is not None:
            image, source = read_image(args.image), str(args.image)
        else:  # the laser light of a measurement capture with the cell file's camera and laser
            cap = measure(args.config, log, board=False)
            image, record, source = cap.stripe_image, cap.record, "capture"
            light = cap.stripe_px is not None
        # The service's map: the floor's mirror images dropped, a capture's laser light fitted
        # on its own (the same capture gives the same points through either door).
        floor = _floor(calib, args.config)
        laser_map = map_laser(image, calib, source, log, floor, light_only=light)
    picture = write_picture(
        map_png_path(args), lambda: map_overlay(image, laser_map, calib, source)
    )
    _warn(picture)
    if args.json:
        out = {**laser_map.summary(with_points=args.points), **picture}
        print_result({**out, "capture": record} if record else out)
    else:
        segs = laser_map.segments
        print(f"{len(laser_map.pixels)} laser points, {len(segs)} segments")
        for i, s in enumerate(segs):
            print(
                f"  segment {i}: {len(s.points_S):5d} points  distance {s.distance_mm:8.1f} mm"
                f"  bearing {s.bearing_deg:7.1f} deg  length {s.length_mm:7.1f} mm"
            )
        if picture["overlay_png"]:
            print(f"picture of the points and their top view: {picture['overlay_png']}")
    return 0
