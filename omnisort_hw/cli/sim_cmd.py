"""`omnisort sim render|dataset|checkerboard-views|scenes|virtual-cell`: the simulated cell's
images, and the simulated cell behind the real protocols."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from omnisort_hw.cli.arg_types import Subcommands, output_folder
from omnisort_hw.cli.virtual_cell_args import add_arguments
from omnisort_hw.errors import InputError


def register(sub: Subcommands) -> None:
    parser = sub.add_parser("sim", help="render images with ground truth from the simulated cell")
    ssub = parser.add_subparsers(dest="sim_command", required=True, metavar="ACTION")

    ren = ssub.add_parser("render", help="render one scene file: NAME.png + NAME.truth.json")
    ren.add_argument("scene", help="scene TOML file, or the name of a shipped scene")
    ren.add_argument("--out", type=output_folder, required=True, help="output folder")
    ren.add_argument("--seed", type=int, default=0, help="seed of the degradation (default 0)")
    ren.add_argument("--degraded", action="store_true", help='"real camera" mode')
    ren.add_argument("--laser", choices=("on", "off"), default=None, help="override [laser].on")
    ren.add_argument("--width", type=int, default=None, help="square image size (default: scene)")
    ren.add_argument("--name", default=None, help="file name stem (default: the scene's name)")
    ren.set_defaults(func=cmd_render)

    ds = ssub.add_parser("dataset", help="render an experiment (one folder per configuration)")
    ds.add_argument("--experiment", default="table3", help="experiment (default table3)")
    ds.add_argument("--n", type=int, default=35, help="number of configurations (default 35)")
    ds.add_argument("--seed", type=int, default=0)
    ds.add_argument("--out", type=output_folder, required=True)
    ds.add_argument("--width", type=int, default=None, help="square image size (default 1920)")
    ds.add_argument("--degraded", action="store_true", help='"real camera" mode')
    ds.add_argument(
        "--effects",
        action="store_true",
        help="through the colour camera's effects as well (crosstalk, chromatic aberration, "
        "bloom, Bayer demosaicing); implies --degraded",
    )
    ds.set_defaults(func=cmd_dataset)

    cv = ssub.add_parser(
        "checkerboard-views", help="calibration screen: a checkerboard at varied poses"
    )
    cv.add_argument("--n", type=int, default=12, help="number of views (default 12)")
    cv.add_argument("--seed", type=int, default=0)
    cv.add_argument("--out", type=output_folder, required=True)
    cv.add_argument("--board", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    cv.add_argument("--square", type=float, default=116.0, help="square size mm (default 116)")
    cv.add_argument("--width", type=int, default=None, help="square image size (default 1920)")
    cv.add_argument("--camera", type=Path, default=None, help="camera.json to render through")
    cv.add_argument("--degraded", action="store_true", help='"real camera" mode')
    cv.set_defaults(func=cmd_views)

    sc = ssub.add_parser("scenes", help="list the shipped scene files")
    sc.set_defaults(func=cmd_scenes)

    vc = ssub.add_parser(
        "virtual-cell",
        help="serve a simulated cell over RTDE, dashboard, Modbus TCP and an MJPEG stream",
    )
    add_arguments(vc)
    vc.set_defaults(func=cmd_virtual_cell)


def _width(value: int | None) -> int | None:
    if value is not None and not 32 <= value <= 8192:
        raise InputError(f"--width must be within [32, 8192], got {value}")
    return value


def cmd_render(args: argparse.Namespace) -> int:
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene, write_render

    scene = sized(load_scene(args.scene), _width(args.width))
    laser = None if args.laser is None else args.laser == "on"
    t0 = time.perf_counter()
    image, truth = render_scene(
        scene, seed=args.seed, degraded=args.degraded or None, laser_on=laser
    )
    img_path, truth_path = write_render(args.out, args.name or scene.name, image, truth)
    print(f"{img_path}  ({time.perf_counter() - t0:.1f} s)")
    print(truth_path)
    return 0


def cmd_dataset(args: argparse.Namespace) -> int:
    from sim_backend.dataset import make_dataset

    index = make_dataset(
        args.out,
        experiment=args.experiment,
        n=args.n,
        seed=args.seed,
        width=_width(args.width),
        degraded=args.degraded,
        effects=args.effects,
    )
    print(index)
    return 0


def cmd_views(args: argparse.Namespace) -> int:
    from sim_backend.dataset import checkerboard_views

    try:
        cols, rows = (int(x) for x in args.board.lower().split("x"))
    except ValueError:
        raise InputError(
            f"--board must look like 9x6 (inner corners), got {args.board!r}"
        ) from None
    if cols < 2 or rows < 2 or args.square <= 0:
        raise InputError(f"--board {args.board} / --square {args.square}: not a checkerboard")
    paths = checkerboard_views(
        args.out,
        n=args.n,
        seed=args.seed,
        width=_width(args.width),
        inner_corners=(cols, rows),
        square_mm=args.square,
        model_file=str(args.camera.resolve()) if args.camera else "",
        degraded=args.degraded,
    )
    json.dump([str(p) for p in paths], sys.stdout, indent=1)
    print()
    return 0


def cmd_scenes(args: argparse.Namespace) -> int:
    from sim_backend.scene import SCENES_DIR, shipped_scenes

    for name in shipped_scenes():
        print(f"{name:<16} {SCENES_DIR / (name + '.toml')}")
    return 0


def cmd_virtual_cell(args: argparse.Namespace) -> int:
    from sim_backend.virtual_cell.run import serve

    return serve(args)
