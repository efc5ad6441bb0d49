"""`omnisort demo`: the cell end to end on the simulated backend, with a rerun log.

1. intrinsics from the simulator's calibration screen (checkerboard views over the whole
   field of view);
2. camera + laser calibration (joint) from one rendered image of the two-sided target at a
   random mounting, compared with the simulator's truth;
3. a laser map of that image;
4. the whole cell through the service: `omnisort serve` on the simulated sorting cell, driven
   over TCP like any client (calibrate -> register_robot -> map -> sort), stopped by SIGTERM;
5. the same through the real drivers: a virtual cell (`omnisort sim virtual-cell`) serves the
   simulated cell over RTDE, Modbus TCP and an MJPEG stream, `omnisort serve` runs the cell file
   of `deploy/cell.virtual.toml` against it, and the sort is checked against its truth.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

from omnisort_hw.cli.arg_types import Subcommands, output_folder

if TYPE_CHECKING:  # the command's heavy imports stay inside it
    import numpy as np

    from omnisort_hw.pipeline.laser_map import LaserMap


def register(sub: Subcommands) -> None:
    demo = sub.add_parser("demo", help="run the simulated cell end to end")
    demo.add_argument("--out", type=output_folder, default=Path("build/demo"))
    demo.add_argument("--seed", type=int, default=7)
    demo.add_argument("--width", type=int, default=960, help="simulated cell camera size (step 4)")
    demo.set_defaults(func=cmd_demo)


def _step(title: str) -> None:
    print(f"\n== {title}", flush=True)


def cmd_demo(args: argparse.Namespace) -> int:
    import numpy as np

    from omnisort_hw.core.camera_io import save_camera_json
    from omnisort_hw.core.checkerboard import BoardSpec
    from omnisort_hw.evaluation.table3 import truth_parameters
    from omnisort_hw.fileio import atomic_write_json
    from omnisort_hw.pipeline.extrinsics import calibrate_system
    from omnisort_hw.pipeline.intrinsics import calibrate_intrinsics
    from omnisort_hw.pipeline.laser_map import map_laser
    from omnisort_hw.runlog import RunLog
    from sim_backend.scene import load_scene
    from sim_backend.scene_images import render_scene, write_render

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    rrd = out / "demo.rrd"
    t_start = time.perf_counter()
    with RunLog(rrd) as log:
        _step("1. fisheye intrinsics (OCamCalib model)")
        from omnisort_hw.pipeline.image_files import read_image
        from sim_backend.dataset import checkerboard_views

        views = checkerboard_views(out / "views", n=10, seed=args.seed, progress=True)
        images = [(p.name, read_image(p)) for p in views]
        board = BoardSpec(9, 6, 116.0)
        source = f"{len(views)} simulated calibration views"
        t0 = time.perf_counter()
        cal = calibrate_intrinsics(images, board, log=log)
        intr = cal.result
        save_camera_json(out / "camera.json", intr.model, **cal.record)
        print(
            f"   {source}: RMS {intr.rms_px:.3f} px, {len(intr.images_used)} used, "
            f"{time.perf_counter() - t0:.1f} s -> {out / 'camera.json'}"
        )

        _step("2. camera + laser calibration from ONE image of the two-sided target (joint)")
        rng = np.random.default_rng(args.seed)
        a = rng.uniform(-10, 10, 5)
        scene = load_scene("two_sided").replace(
            camera={"roll_deg": a[0], "pitch_deg": a[1], "yaw_deg": a[2]},
            laser={"roll_deg": a[3], "pitch_deg": a[4]},
        )
        image, truth = render_scene(scene, seed=args.seed)
        img_path, _ = write_render(out, "two_sided", image, truth)
        from omnisort_hw.core.camera_model import OcamModel
        from omnisort_hw.core.radiometry import ToneCurve

        model = OcamModel.from_dict(truth["camera"])
        calib = calibrate_system(
            image,
            model,
            "two-sided",
            "joint",
            separation_mm=truth["target"]["separation_mm"],
            source=str(img_path),
            log=log,
            tone=ToneCurve.parse(truth["render"]["tone_curve"]),  # the simulated camera's curve
        )
        atomic_write_json(out / "system.json", calib.to_json())
        want = truth_parameters(truth)
        print(f"   {'parameter':<20} {'truth':>10} {'joint':>10} {'error':>9} {'std':>8}")
        for key, value in calib.parameters().items():
            print(
                f"   {key:<20} {want[key]:10.4f} {value:10.4f} {value - want[key]:9.4f} "
                f"{calib.std.get(key, float('nan')):8.4f}"
            )
        print(f"   solved in {calib.elapsed_s * 1000:.0f} ms -> {out / 'system.json'}")

        _step("3. laser map of the same image")
        laser_map = map_laser(image, calib, str(img_path), log)
        segs = laser_map.segments
        for i, s in enumerate(segs):
            print(
                f"   segment {i}: {len(s.points_S):4d} points, {s.distance_mm:7.1f} mm from the "
                f"axis at bearing {s.bearing_deg:6.1f} deg"
            )
        png = write_overview(out / "demo.png", image, laser_map, calib.parameters(), want)
        print(f"   picture of this step: {png}")
        summary = {
            "intrinsics_rms_px": intr.rms_px,
            "system": calib.parameters(),
            "truth": want,
            "segments": [s.summary() for s in segs],
        }

    _step("4. the whole cell through the service protocol (simulated sorting cell)")
    from omnisort_hw.service.demo import run as run_service_demo

    cell = run_service_demo(out / "cell", width=args.width)
    summary["cell"] = cell
    atomic_write_json(out / "summary.json", summary)
    ok = all(step["ok"] for step in cell["steps"]) and cell["exit_code"] == 0
    print(
        f"   service exit code {cell['exit_code']} after SIGTERM; cell run log: {cell.get('rrd')}"
    )

    _step("5. the same cell through the real drivers (ur-rtde, pymodbus, OpenCV) on a virtual cell")
    from omnisort_hw.service import virtual_cell_demo as virtual_demo

    virtual = virtual_demo.run(out / "virtual", width=args.width)
    virtual_demo.report(virtual)
    summary["virtual_cell"] = {k: v for k, v in virtual.items() if k != "truth_before"}
    atomic_write_json(out / "summary.json", summary)
    ok = ok and virtual_demo.ok(virtual)
    print(f"\nrun log: {rrd} (omnisort review {rrd}); total {time.perf_counter() - t_start:.1f} s")
    return 0 if ok else 1


def write_overview(
    path: Path,
    image: np.ndarray,
    laser_map: LaserMap,
    found: dict[str, float],
    truth: dict[str, float],
) -> Path:
    """The calibration image with the laser stripe found (green) and each segment's distance,
    and the calibrated parameters against the truth: a picture of one run."""
    import cv2

    from omnisort_hw.core.overlays import draw_dots, write_png

    canvas = draw_dots(image.copy(), laser_map.pixels, (0, 220, 0), max(2, image.shape[1] // 600))
    small = cv2.resize(canvas, (800, round(800 * canvas.shape[0] / canvas.shape[1])))
    lines = [f"{k}: {found[k]:.3f} (truth {truth[k]:.3f})" for k in found]
    lines += [f"segment {i}: {s.distance_mm:.0f} mm" for i, s in enumerate(laser_map.segments)]
    cv2.rectangle(small, (0, 0), (380, 14 + 20 * len(lines)), (0, 0, 0), -1)
    for i, text in enumerate(lines):
        org = (10, 22 + 20 * i)
        cv2.putText(
            small, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA
        )
    return write_png(path, small)
