"""The service demo on the real drivers: `omnisort serve` with a cell file whose camera, laser
and arm are a virtual cell, driven over TCP (calibrate -> register_robot -> map -> sort), then
checked against the virtual cell's truth: every cube in the bin of its colour, no collision.

    python -m omnisort_hw.service.virtual_cell_demo [--out build/demo-virtual] [--width 960]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from sim_backend.virtual_cell.cell_file import cell_file_text
from sim_backend.virtual_cell.launcher import VirtualCellProcess


def check_truth(truth: dict[str, Any], cubes: int | None = None) -> list[str]:
    """What is wrong in the cell after a sort of every cube (`cubes` None) or of `cubes` of
    them: empty when each cube asked for is in its own bin, the others in none, and nothing
    collided."""
    placed = [c for c in truth["cubes"] if c["bin"] is not None]
    problems = [
        f"{c['color']} cube {c['index']} is in {c['bin'] or 'no bin'} at "
        f"{[round(v) for v in c['center_S_mm']]}"
        for c in truth["cubes"]
        if c["bin"] != c["color"] and (cubes is None or c["bin"] is not None)
    ]
    if cubes is not None and len(placed) != cubes:
        problems.append(f"{len(placed)} cubes in a bin, {cubes} asked for")
    problems += [f"collision: {event}" for event in truth["collisions"]]
    return problems


def run(
    out: Path,
    width: int = 960,
    host: str | None = None,
    views: int = 10,
    cubes: int | None = None,
) -> dict[str, Any]:
    """Start a virtual cell, run the service demo against it with the real drivers, check the
    truth; the summary (steps, truth, figures). `cubes`: how many the sort takes (None: all)."""
    from omnisort_hw.service.demo import run as run_service_demo

    out.mkdir(parents=True, exist_ok=True)
    print(f"starting a virtual cell (sorting scene, {width}x{width})", flush=True)
    with VirtualCellProcess("sorting", host=host, width=width, unlock_delay_s=5.0) as vc:
        print(f"virtual cell ready on {vc.host} (log {vc.log_path})", flush=True)
        config = out / "cell.virtual.toml"
        config.write_text(cell_file_text(vc.host, state_dir="state", log_dir="logs"))
        before = vc.truth()
        t0 = time.monotonic()
        summary = run_service_demo(out, width, views, config=config, cubes=cubes)
        summary["seconds"] = round(time.monotonic() - t0, 1)
        truth = vc.truth()
        status = vc.control("status")
    summary["host"] = vc.host
    summary["truth_before"] = before
    summary["truth"] = truth
    summary["problems"] = check_truth(truth, cubes)
    sort = next((s for s in summary["steps"] if s["step"] == "sort"), None)
    placed = sum(c["bin"] == c["color"] for c in truth["cubes"])
    summary["cubes_in_their_bin"] = placed
    summary["cubes"] = len(truth["cubes"])
    if sort is not None and placed:
        summary["seconds_per_pick"] = round(sort["seconds"] / placed, 2)
    summary["controller"] = {k: status[k] for k in ("motions", "scripts", "late_ticks")}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def ok(summary: dict[str, Any]) -> bool:
    """Every step answered, the service stopped cleanly, every cube is in its bin, no collision."""
    return (
        all(s["ok"] for s in summary["steps"])
        and summary["exit_code"] == 0
        and not summary["problems"]
    )


def report(summary: dict[str, Any]) -> None:
    print(
        f"   virtual cell truth: {summary['cubes_in_their_bin']}/{summary['cubes']} cubes in "
        f"the bin of their colour, {len(summary['truth']['collisions'])} collisions"
        + (f", {summary['seconds_per_pick']} s per pick" if "seconds_per_pick" in summary else "")
    )
    for problem in summary["problems"]:
        print(f"   PROBLEM: {problem}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m omnisort_hw.service.virtual_cell_demo", description=__doc__
    )
    ap.add_argument("--out", type=Path, default=Path("build/demo-virtual"))
    ap.add_argument("--width", type=int, default=960)
    ap.add_argument("--host", default=None, help="loopback address (default: a free 127.a.b.c)")
    args = ap.parse_args(argv)
    summary = run(args.out, args.width, args.host)
    report(summary)
    return 0 if ok(summary) else 1


if __name__ == "__main__":
    sys.exit(main())
