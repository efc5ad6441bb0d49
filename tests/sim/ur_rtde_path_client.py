"""A plain ur-rtde client that plays one path on a virtual cell and times it on the
controller's clock: `python -m tests.sim.ur_rtde_path_client HOST ROWS_JSON`.

ROWS_JSON is a list of ["joint" | "linear", [6 values, speed, accel, blend]] in UR units. The
path goes through ur-rtde's own `movePath` (asynchronous); the RTDE output is polled and the
motion's start and end are read from the controller's `timestamp` (first sample with a
non-zero joint speed; first sample at rest on the final joints). Prints one JSON object.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main(host: str, rows: list) -> dict:
    import rtde_control
    import rtde_receive

    rcv = rtde_receive.RTDEReceiveInterface(host)
    ctl = rtde_control.RTDEControlInterface(host)
    path = rtde_control.Path()
    for kind, row in rows:
        if kind == "linear":
            move, pos = rtde_control.PathEntry.MoveL, rtde_control.PathEntry.PositionTcpPose
        else:
            move, pos = rtde_control.PathEntry.MoveJ, rtde_control.PathEntry.PositionJoints
        path.addEntry(rtde_control.PathEntry(move, pos, [float(v) for v in row]))
    out: dict = {"accepted": bool(ctl.movePath(path, True))}
    samples: list[tuple[float, list[float], bool]] = []
    start = end = None
    last_ts = -1.0
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        ts = rcv.getTimestamp()
        if ts == last_ts:
            time.sleep(0.0002)
            continue
        last_ts = ts
        q = list(rcv.getActualQ())
        moving = bool(np.any(np.abs(rcv.getActualQd()) > 0.0))
        samples.append((ts, q, moving))
        if start is None and moving:
            start = ts
        if (
            start is not None
            and not moving
            and not ctl.getAsyncOperationProgressEx().isAsyncOperationRunning()
        ):
            end = ts
            break
    # the last sample before rest may have been missed by polling: the end is the first
    # sample seen at rest; its uncertainty is one controller tick
    stamps = np.array([s[0] for s in samples])
    during = stamps[(stamps >= (start or 0.0)) & (stamps <= (end or np.inf))]
    out.update(
        start=start,
        end=end,
        max_tick_gap=float(np.max(np.diff(during))) if during.size > 1 else None,
        q=[s[1] for s in samples],
        final_q=list(rcv.getActualQ()),
    )
    ctl.stopScript()
    ctl.disconnect()
    rcv.disconnect()
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], json.loads(sys.argv[2]))), flush=True)
