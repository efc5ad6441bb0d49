"""Real light: the stripe extractor on real photographs of a laser line across a checkerboard
card, judged against a reference built from each photograph (`evaluation.real_stripe`).

`python -m benchmarks --only real_light --photos DIR`: every PNG and JPEG under DIR, grouped
by the folder that holds it. A folder whose path names "green" or "blue" holds photographs of
a laser of that colour, any other a red one (a real camera's crosstalk makes the colour of a
bright line on white paper no safe guess). A photograph on which no laser line is found is a
laser-off photograph: every point the extractor finds there is a phantom. The photographs
stay outside the project (docs/real_light.md names the public sets used in development); only
these figures enter it.

`before` keeps the figures of the first run (the extractor before the real-light rules), `now`
is this run's.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.evaluation.camera_measures import HALO_AT_PX, chromatic_shift, crosstalk, halo
from omnisort_hw.evaluation.real_stripe import (
    board_hull,
    judge,
    reference_stripe,
    summarise,
)

HERE = Path(__file__).resolve().parent


def measure(photos: Path) -> dict[str, Any]:
    """Per folder of `photos`: the summary of every photograph with a laser line."""
    files = sorted(p for p in photos.rglob("*") if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    if not files:
        raise FileNotFoundError(f"{photos}: no PNG or JPEG photographs under it")
    sets: dict[str, list[dict[str, Any]]] = {}
    dark: dict[str, list[int]] = {}  # per folder: points found on each laser-off photograph
    camera: dict[str, dict[str, list[Any]]] = {}  # per folder: the camera's measures
    t_extract = 0.0
    for i, path in enumerate(files):
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        name = " ".join(path.parent.relative_to(photos).parts[-2:])  # no "/": figure paths
        if bgr is None:
            raise ValueError(f"{path}: not an image OpenCV reads")
        colour = next((c for c in ("green", "blue") if c in str(path.parent).lower()), "red")
        ref = reference_stripe(bgr, colour)
        cam = camera.setdefault(name, {"crosstalk": [], "chromatic": [], "halo": []})
        cam["chromatic"].append(chromatic_shift(bgr))
        if ref is not None:
            cam["crosstalk"].append(crosstalk(bgr, ref, colour))
            cam["halo"].append(halo(bgr, ref, colour))
        t0 = time.perf_counter()
        pts = laser_stripe_points(bgr, color=colour)  # the laser as the cell file names it
        t_extract += time.perf_counter() - t0
        if ref is None:
            dark.setdefault(name, []).append(len(pts))
            print(f"   [{i + 1}/{len(files)}] {path.name}: no laser, {len(pts)} points", flush=True)
            continue
        row = judge(ref, board_hull(bgr), pts)
        row["colour"] = colour
        sets.setdefault(f"{name} ({colour})", []).append(row)
        print(f"   [{i + 1}/{len(files)}] {path.name}: {row}", flush=True)
    out: dict[str, Any] = {k: summarise(v) for k, v in sorted(sets.items())}
    for name, counts in sorted(dark.items()):
        out[f"{name} (laser off)"] = {
            "photos": len(counts),
            "with_phantoms": sum(n > 0 for n in counts),
            "phantom_points_max": max(counts),
            "phantom_points_total": sum(counts),
        }
    out["_extract_s_mean"] = round(t_extract / len(files), 3)
    out["_camera"] = {name: _camera_summary(m) for name, m in sorted(camera.items())}
    return out


def _camera_summary(m: dict[str, list[Any]]) -> dict[str, Any]:
    """Medians over a folder's photographs of each camera measure, and their spread."""

    def spread(rows: list[dict[str, float]], key: str) -> list[float] | None:
        vals = [r[key] for r in rows if r is not None and key in r]
        if not vals:
            return None
        return [round(float(v), 3) for v in np.percentile(vals, [10, 50, 90])]

    xt = [r for r in m["crosstalk"] if r is not None]
    ca = [r for r in m["chromatic"] if r is not None]
    halos = np.array([h for h in m["halo"] if h is not None], float)
    return {
        "crosstalk_p10_p50_p90": {k: spread(xt, k) for k in ("red", "green", "blue")},
        "crosstalk_photos": len(xt),
        "chromatic_px_at_corner_p10_p50_p90": {k: spread(ca, k) for k in ("red", "blue")},
        "chromatic_photos": len(ca),
        "halo_at_px": list(HALO_AT_PX),
        "halo_share_median": (
            [round(float(v), 3) for v in np.nanmedian(halos, axis=0)] if len(halos) else None
        ),
        "halo_photos": len(halos),
    }


OFF_RENDERS = 50  # laser-off renders of the sorting cell, unseen seeds
OFF_WIDTH = 960  # the cell's frame size


def laser_off_renders(n: int = OFF_RENDERS, width: int = OFF_WIDTH) -> dict[str, Any]:
    """The cluttered sorting cell (red, green, blue and yellow cubes and bins, the floor
    board's black print, the arm's metal) rendered laser off through the colour camera's
    effects, `n` seeds: the points the extractor returns from one image (phantoms, every
    one), and what its chains held before the line rule (`core.laser_presence`) dropped them."""
    from omnisort_hw.core.laser_stripe import laser_stripe_points_stats
    from sim_backend.scene import load_scene, sized, with_camera_effects
    from sim_backend.scene_images import render_scene

    scene = with_camera_effects(sized(load_scene("sorting"), width))
    now, without = [], []
    for k, seed in enumerate(range(1000, 1000 + n)):
        off, _ = render_scene(scene, seed=seed, laser_on=False, with_truth=False)
        pts, stats = laser_stripe_points_stats(off)
        held = stats.presence.points if stats.presence is not None else len(pts)
        now.append(len(pts))
        without.append(held)
        print(f"   laser-off render {k + 1}/{n}: {len(pts)} points ({held} before the line rule)")

    def summary(counts: list[int]) -> dict[str, int]:
        return {
            "renders": len(counts),
            "with_phantoms": sum(c > 0 for c in counts),
            "phantom_points_max": max(counts),
            "phantom_points_total": sum(counts),
        }

    return {"width_px": width, "now": summary(now), "without_line_rule": summary(without)}


def run(shared: Path, photos: Path) -> dict[str, Any]:
    now = measure(photos)
    now["_laser_off_renders"] = laser_off_renders()
    saved = HERE / "results.json"
    before = None
    if saved.exists():
        before = json.loads(saved.read_text()).get("real_light", {}).get("before")
    return {"photos": str(photos.name), "before": before or now, "now": now}
