"""Simulator speed: a 1920 x 1920 fisheye frame with the laser, on one core (goal: <= 2 s).

The measurement runs in a child process pinned to one CPU with every thread pool limited to
one thread. Figures: the per-camera remap tables (built once per camera configuration and
cached); a warm frame (median of several frames of one world: what the simulated camera
pays per grab: raster of the moving bodies, shading, adaptive supersampling, laser); a cold
frame (a new world with the same camera: what each dataset image pays, including the exact
static hits of every pixel); the truth; and the "real camera" mode's extra cost.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
ONE_THREAD = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
}


def _measure(frames: int = 5) -> dict[str, Any]:
    """Runs in the pinned child: time the renderer on the shipped scenes."""
    import time

    import cv2
    import numpy as np

    cv2.setNumThreads(1)
    from sim_backend.fisheye_atlas import geometry_for
    from sim_backend.render import render_frame
    from sim_backend.scene import load_scene
    from sim_backend.scene_images import camera_model_for, finish_image
    from sim_backend.truth import build_truth
    from sim_backend.world import SimWorld

    out: dict[str, Any] = {}
    scene = load_scene("two_sided")
    model = camera_model_for(scene)
    world = SimWorld(scene)
    t0 = time.perf_counter()
    geometry_for(model, world.R_SC, scene.render.face_px, scene.camera.image_circle_fov_deg)
    out["remap_tables_build_s"] = round(time.perf_counter() - t0, 3)
    for name in ("two_sided", "sorting"):
        sc = load_scene(name)
        w = world if name == "two_sided" else SimWorld(sc)
        times, parts = [], []
        for _ in range(frames):
            t0 = time.perf_counter()
            result = render_frame(w, model, laser_on=True)
            finish_image(w, result, 0, False)
            times.append(time.perf_counter() - t0)
            parts.append(result.stats)
        fresh = SimWorld(sc)
        t0 = time.perf_counter()
        finish_image(fresh, render_frame(fresh, model, laser_on=True), 0, False)
        out[f"{name}_cold_frame_1920_laser_s"] = round(time.perf_counter() - t0, 3)
        fresh.close()
        best = int(np.argsort(times)[len(times) // 2])
        out[f"{name}_frame_1920_laser_s"] = round(float(np.median(times)), 3)
        for key in ("raster_s", "shade_s", "supersample_s"):
            out[f"{name}_{key}"] = round(parts[best][key], 3)
        out[f"{name}_supersampled_pixels"] = int(parts[best]["supersampled_pixels"])
        t0 = time.perf_counter()
        build_truth(w, model, True)
        out[f"{name}_truth_s"] = round(time.perf_counter() - t0, 3)
    t0 = time.perf_counter()
    finish_image(world, result, 1, True)
    out["degradation_s"] = round(time.perf_counter() - t0, 3)
    out["frames_timed"] = frames
    return out


def run(shared: Path) -> dict[str, Any]:
    """`make bench` entry: measure in a child process pinned to one core."""
    env = {**os.environ, **ONE_THREAD, "PYTHONPATH": str(ROOT)}
    cpu = sorted(os.sched_getaffinity(0))[-1]
    code = (
        "import json, os, sys; "
        f"os.sched_setaffinity(0, {{{cpu}}}); "
        "from benchmarks.bench_sim import _measure; "
        "print('RESULT ' + json.dumps(_measure()))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"bench_sim child failed: {proc.stderr.strip()[-2000:]}")
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT "))
    figures = json.loads(line[len("RESULT ") :])
    figures["pinned_cpu"] = cpu
    figures["goal_frame_s"] = 2.0
    return figures


if __name__ == "__main__":
    print(json.dumps(run(ROOT.parent / "shared"), indent=2))
