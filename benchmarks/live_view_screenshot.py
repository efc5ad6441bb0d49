"""The README's live-view picture: `omnisort serve` on the simulated cell with `[logging]
live = true`, a sort started over TCP, a separate process (rerun's CLI) saving what the live
gRPC stream delivers while the sort runs, and rerun's native viewer rendering that under a
virtual display (Xvfb) with its own `--screenshot-to`. (A window grab of the viewer connected
to the stream is black under Xvfb: the Vulkan software rasteriser presents outside what xwd
reads; the viewer's own screenshot of a live connection is taken before the buffered data
has arrived.)

    xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python -m benchmarks.live_view_screenshot

Needs Xvfb and a Vulkan software rasteriser (Debian: xvfb, mesa-vulkan-drivers);
writes docs/images/live_view.png. Not part of `make test` or `make bench`.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import tempfile
import time
from pathlib import Path

from omnisort_hw.cli.review_cmd import save_live_command, viewer_command
from omnisort_hw.service.client import Client
from omnisort_hw.service.demo import calibrate_from_truth, write_config
from omnisort_hw.service.launch import start_service

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "live_view.png")
    ap.add_argument("--width", type=int, default=640, help="simulated camera size")
    ap.add_argument("--cubes", type=int, default=2, help="take it after this many picks")
    ap.add_argument("--settle", type=float, default=3.0, help="s for the viewer to catch up")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        config = write_config(tmp, args.width)
        port = _free_port()
        text = config.read_text().replace(
            '[logging]\nlog_dir = "logs"\n',
            f'[logging]\nlog_dir = "logs"\nlive = true\nlive_port = {port}\n'
            'live_memory_limit = "256MiB"\n',
        )
        config.write_text(text)
        calibrate_from_truth(config)
        with (
            start_service(config, tmp / "run") as svc,
            Client(svc.host, svc.port, timeout_s=600) as c,
        ):
            received = tmp / "live.rrd"
            rid = c.send("sort")
            viewer = subprocess.Popen(
                save_live_command(f"127.0.0.1:{port}", received),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            try:
                with Client(svc.host, svc.port, timeout_s=30) as poll:
                    deadline = time.monotonic() + 300
                    while time.monotonic() < deadline:
                        rep = poll.call("status")
                        assert rep.get("ok"), rep
                        st = rep["result"]
                        done = [e for e in (st.get("job") or {}).get("progress", []) if "cube" in e]
                        if len(done) >= args.cubes or st["job"] is None:
                            break
                        time.sleep(0.5)
                time.sleep(args.settle)
            finally:
                viewer.terminate()
                viewer.wait(20)
            grab = subprocess.run(
                [
                    *viewer_command(),
                    str(received),
                    "--window-size",
                    "1600x1000",
                    "--screenshot-to",
                    str(args.out),
                ],
                capture_output=True,
                timeout=240,
            )
            print(f"stream received up to state {st['state']}, {len(done)} cube(s): {args.out}")
            if grab.returncode != 0:
                print(grab.stderr.decode(errors="replace")[-2000:])
                return 1
            reply = c.read_reply()
            assert reply["id"] == rid
            print("sort:", "ok" if reply["ok"] else reply["error"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
