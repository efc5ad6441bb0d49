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

from omnisort_hw.core.laser_stripe import laser_stripe_points
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
    t_extract = 0.0
    for i, path in enumerate(files):
        bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
        name = str(path.parent.relative_to(photos))
        if bgr is None:
            raise ValueError(f"{path}: not an image OpenCV reads")
        colour = next((c for c in ("green", "blue") if c in str(path.parent).lower()), "red")
        ref = reference_stripe(bgr, colour)
        t0 = time.perf_counter()
        pts = laser_stripe_points(bgr)
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
    return out


def run(shared: Path, photos: Path) -> dict[str, Any]:
    now = measure(photos)
    saved = HERE / "results.json"
    before = None
    if saved.exists():
        before = json.loads(saved.read_text()).get("real_light", {}).get("before")
    return {"photos": str(photos.name), "before": before or now, "now": now}
