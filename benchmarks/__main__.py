"""`make bench`: run every benchmark module, print its figures, save them to results.json.

Usage: python -m benchmarks [--shared DIR] [--only NAME ...] [--photos DIR]

`--photos DIR`: the real photographs that `real_light` measures on (kept outside the project:
see docs/real_light.md); without it that benchmark is skipped and its saved figures stay.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import os
import platform
import sys
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent


def machine() -> dict[str, Any]:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version()}


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument("--shared", type=Path, default=HERE.parent.parent / "shared")
    parser.add_argument("--only", nargs="*", default=None, help="module names without bench_")
    parser.add_argument("--photos", type=Path, default=None, help="real photographs' folder")
    args = parser.parse_args()
    names = sorted(p.stem for p in HERE.glob("bench_*.py"))
    if args.only:
        names = [n for n in names if n.removeprefix("bench_") in args.only]
    out_path = HERE / "results.json"
    # The shared record describes the machine of a full run; a partial run (--only) names
    # its own in each section it writes, so the other sections keep theirs.
    here = machine()
    results: dict[str, Any] = {} if args.only else {"machine": here}
    failed = 0
    for name in names:
        module = importlib.import_module(f"benchmarks.{name}")
        print(f"== {name}", flush=True)
        wants_photos = "photos" in inspect.signature(module.run).parameters
        if wants_photos and args.photos is None:
            print("   skipped: it measures on real photographs (--photos DIR)", flush=True)
            continue
        t0 = time.perf_counter()
        try:
            if wants_photos:
                figures = module.run(args.shared, photos=args.photos)
            else:
                figures = module.run(args.shared)
        except Exception as exc:
            failed += 1
            print(f"   FAILED: {type(exc).__name__}: {exc}", flush=True)
            continue
        figures["_wall_s"] = round(time.perf_counter() - t0, 2)
        figures["_date"] = datetime.now(UTC).isoformat(timespec="seconds")
        if args.only:
            figures["_machine"] = here
        results[name.removeprefix("bench_")] = figures
        for key, value in figures.items():
            print(f"   {key:<44} {value}", flush=True)
    # Read again just before writing: another run may have saved its figures meanwhile.
    saved: dict[str, Any] = json.loads(out_path.read_text()) if out_path.exists() else {}
    saved.update(results)
    tmp = out_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(saved, indent=2, sort_keys=True) + "\n")
    tmp.replace(out_path)
    print(f"figures saved to {out_path}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
