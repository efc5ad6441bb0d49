"""The service demo: `omnisort serve` on the simulated cell, driven through the protocol.

    python -m omnisort_hw.service.demo [--out build/demo-service] [--width 960]

Renders checkerboard views for the intrinsics, writes a cell configuration for the simulated
`sorting` scene, starts the service as systemd would (READY over a notify socket), then sends
calibrate (intrinsics, extrinsics) -> register_robot -> map -> sort over TCP like any client,
stops it with SIGTERM and prints a summary and the path of the `.rrd` file. Nothing here
touches the devices or the core directly: everything goes through the protocol.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omnisort_hw.pipeline.replies import (
    CalibrateReply,
    ExtrinsicsReply,
    IntrinsicsReply,
    MapReply,
    RegisterReply,
    SortReply,
)

if TYPE_CHECKING:
    from omnisort_hw.service.client import Client

SCENE = "sorting"


def write_config(out: Path, width: int) -> Path:
    """`out/cell.toml`: the simulated cell of `deploy/cell.sim.toml` (the same generator) with
    its camera at `width` px and its state and logs under `out`."""
    from sim_backend.virtual_cell.cell_file import sim_cell_file_text

    path = out / "cell.toml"
    path.write_text(sim_cell_file_text(SCENE, width, state_dir="state", log_dir="logs"))
    return path


def calibrate_from_truth(config: Path) -> None:
    """Write camera.json and system.json (with the robot base) of the simulated cell of
    `config` from the simulator's truth: for benchmarks and tests that exercise the service,
    not the calibration (the demo itself calibrates through the protocol)."""
    from datetime import UTC, datetime

    from omnisort_hw.cell.cell import Cell
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.errors import NotAvailableError
    from sim_backend.devices import SimCamera

    cell = Cell.from_settings(load_cell_config(config))
    try:
        cell.connect()
        cam = cell.devices.camera
        if not isinstance(cam, SimCamera):
            raise NotAvailableError(
                f"{config}: [camera] is {type(cam).__name__}, not the simulated camera "
                '(backend = "sim"), so there is no truth to calibrate from'
            )
        cam.grab(with_truth=True)
        truth = cam.last_truth
        if truth is None:
            raise NotAvailableError(f"{config}: the simulated camera kept no truth of its frame")
        system = {k: truth[k] for k in ("camera", "camera_rotation", "laser_plane", "target")}
        system.update(
            method="truth",
            residuals={},
            std={},
            created=datetime.now(UTC).isoformat(timespec="seconds"),
            robot_base=truth["robot_base"],
        )
        cell.store.save_camera(dict(truth["camera"]), camera_serial=cam.serial)
        cell.store.save_system(system, camera_serial=cam.serial)
    finally:
        cell.close()


def _intrinsics_brief(res: CalibrateReply) -> str:
    assert isinstance(res, IntrinsicsReply)
    return f"rms {res.rms_px:.3f} px from {res.images_used} images -> {res.path}"


def _extrinsics_brief(res: CalibrateReply) -> str:
    assert isinstance(res, ExtrinsicsReply)
    p = res.parameters
    return (
        f"{res.method}: camera roll/pitch/yaw {p['cam_roll_deg']:.2f}/"
        f"{p['cam_pitch_deg']:.2f}/{p['cam_yaw_deg']:.2f} deg, laser at "
        f"{p['laser_distance_mm']:.1f} mm -> {res.path}"
    )


def _register_brief(res: RegisterReply) -> str:
    xyz = res.robot_base["xyz_mm"]
    return f"robot base at [{xyz[0]:.1f}, {xyz[1]:.1f}, {xyz[2]:.1f}] mm (S)"


def _map_brief(res: MapReply) -> str:
    return f"{res.points_on_plane} laser points, {len(res.segments)} segments"


def _sort_brief(res: SortReply) -> str:
    t = res.totals
    return f"{t.sorted}/{t.cubes} cubes sorted, {t.skipped} skipped, {t.failed} failed"


def run(
    out: Path,
    width: int = 960,
    views: int = 10,
    config: Path | None = None,
    cubes: int | None = None,
) -> dict[str, Any]:
    """Run the demo into `out`; returns the summary (steps, replies, .rrd path, exit code).
    `config` is a cell file to serve instead of the simulated cell's (the virtual cell's);
    `cubes`: how many the sort takes (None: all)."""
    from omnisort_hw.pipeline.requests import CalibrateRequest, SortRequest
    from omnisort_hw.service.client import Client, CommandError
    from omnisort_hw.service.launch import start_service
    from sim_backend.dataset import checkerboard_views

    out.mkdir(parents=True, exist_ok=True)
    views_dir = out / "views"
    print(f"rendering {views} checkerboard views ({width}x{width}) into {views_dir}", flush=True)
    checkerboard_views(views_dir, n=views, seed=1, width=width, progress=False)
    config = config or write_config(out, width)
    print(f"starting omnisort serve --config {config}", flush=True)
    svc = start_service(config, out)
    folder = str(views_dir.resolve())
    intrinsics = CalibrateRequest(what="intrinsics", folder=folder, square_mm=116.0)
    extrinsics = CalibrateRequest(what="extrinsics", target="two-sided")
    steps: list[tuple[str, Callable[[Client], str]]] = [
        ("calibrate intrinsics", lambda c: _intrinsics_brief(c.calibrate(intrinsics))),
        ("calibrate extrinsics", lambda c: _extrinsics_brief(c.calibrate(extrinsics))),
        ("register_robot", lambda c: _register_brief(c.register_robot())),
        ("map", lambda c: _map_brief(c.map())),
        ("sort", lambda c: _sort_brief(c.sort(SortRequest(max_objects=cubes)))),
    ]
    summary: dict[str, Any] = {"port": svc.port, "steps": []}
    try:
        with Client(svc.host, svc.port, timeout_s=900) as c:
            for title, step in steps:
                t0 = time.monotonic()
                try:
                    ok, line = True, step(c)
                except CommandError as exc:
                    ok, line = False, f"error {exc.code}: {exc.message}"
                dt = time.monotonic() - t0
                print(f"  {title:<22} {dt:6.1f} s  {line}", flush=True)
                summary["steps"].append(
                    {"step": title, "ok": ok, "seconds": round(dt, 2), "summary": line}
                )
            status = c.status()
            summary["state"] = status["state"]
            summary["rrd"] = status["rrd"]
            summary["calibration"] = {
                k: v["health"] for k, v in status["calibration"]["files"].items()
            }
    finally:
        summary["exit_code"] = svc.stop()
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m omnisort_hw.service.demo", description=__doc__)
    ap.add_argument("--out", type=Path, default=Path("build/demo-service"))
    ap.add_argument("--width", type=int, default=960, help="simulated camera image size")
    ap.add_argument("--views", type=int, default=10, help="checkerboard views for intrinsics")
    args = ap.parse_args(argv)
    summary = run(args.out, args.width, args.views)
    ok = all(s["ok"] for s in summary["steps"]) and summary["exit_code"] == 0
    print(f"\nservice stopped with exit code {summary['exit_code']} (SIGTERM)")
    print(f"calibration files: {summary.get('calibration')}")
    print(f"run log: {summary.get('rrd')}  (omnisort review FILE)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
