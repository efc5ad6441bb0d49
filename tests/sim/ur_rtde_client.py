"""A plain ur-rtde client run against a virtual cell: `python -m tests.sim.ur_rtde_client HOST`.

Uses only ur-rtde (and one control-channel line to inject a protective stop) and prints one
JSON object with what it saw. It runs in its own process because ur-rtde's constructors hold
the GIL without a timeout; the test bounds it with the subprocess timeout.
"""

from __future__ import annotations

import json
import socket
import sys
import time

import numpy as np


def control(host: str, cmd: str) -> None:
    with socket.create_connection((host, 30111), timeout=5) as s:
        s.sendall(json.dumps({"cmd": cmd}).encode() + b"\n")
        s.makefile().readline()


def wait_until(fn, timeout_s: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if fn():
            return True
        time.sleep(0.005)
    return bool(fn())


def main(host: str) -> dict:
    import dashboard_client
    import rtde_control
    import rtde_io
    import rtde_receive

    out: dict = {}
    rcv = rtde_receive.RTDEReceiveInterface(host)
    ctl = rtde_control.RTDEControlInterface(host)
    io = rtde_io.RTDEIOInterface(host)
    db = dashboard_client.DashboardClient(host)
    db.connect()
    out["polyscope"] = db.polyscopeVersion()
    out["robotmode"] = db.robotmode()
    q0 = np.asarray(rcv.getActualQ())
    target = q0 + np.deg2rad([12.0, -6.0, 8.0, 5.0, -4.0, 10.0])
    t0 = time.monotonic()
    out["movej_ok"] = ctl.moveJ(list(target), 1.05, 1.4)
    out["movej_s"] = time.monotonic() - t0
    time.sleep(0.02)
    out["movej_err_deg"] = float(np.max(np.abs(np.rad2deg(np.asarray(rcv.getActualQ()) - target))))
    pose = np.asarray(rcv.getActualTCPPose())
    goal = pose.copy()
    goal[:3] += [0.06, -0.04, 0.05]
    t0 = time.monotonic()
    out["movel_ok"] = ctl.moveL(list(goal), 0.25, 1.2)
    out["movel_s"] = time.monotonic() - t0
    time.sleep(0.02)
    now = np.asarray(rcv.getActualTCPPose())
    out["movel_err_mm"] = float(np.linalg.norm(now[:3] - goal[:3]) * 1000.0)
    out["movel_rot_err"] = float(np.linalg.norm(now[3:] - goal[3:]))
    out["protective_before"] = rcv.isProtectiveStopped()
    out["set_do_ok"] = io.setStandardDigitalOut(2, True)
    out["do_bit"] = wait_until(lambda: (rcv.getActualDigitalOutputBits() >> 2) & 1 == 1)
    io.setStandardDigitalOut(2, False)
    out["do_cleared"] = wait_until(lambda: (rcv.getActualDigitalOutputBits() >> 2) & 1 == 0)
    # Asynchronous move interrupted by a protective stop, unlock, re-upload, move again.
    out["async_ok"] = ctl.moveJ(list(q0), 0.5, 1.0, True)
    out["async_running"] = ctl.getAsyncOperationProgressEx().isAsyncOperationRunning()
    time.sleep(0.2)
    control(host, "protective_stop")
    out["protective_seen"] = wait_until(rcv.isProtectiveStopped)
    out["safety_mode"] = rcv.getSafetyMode()
    out["program_running_after_stop"] = not wait_until(lambda: not ctl.isProgramRunning())
    out["movej_refused_in_stop"] = not ctl.moveJ(list(q0), 0.5, 1.0)
    time.sleep(0.3)
    db.unlockProtectiveStop()
    out["unlocked"] = wait_until(lambda: not rcv.isProtectiveStopped())
    out["reupload_ok"] = ctl.reuploadScript()
    wait_until(ctl.isProgramRunning)
    out["movej_after_ok"] = ctl.moveJ(list(q0), 1.05, 1.4)
    out["movej_after_err_deg"] = float(
        np.max(np.abs(np.rad2deg(np.asarray(rcv.getActualQ()) - q0)))
    )
    ctl.stopScript()
    for iface in (ctl, io, rcv):
        iface.disconnect()
    db.disconnect()
    return out


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1])), flush=True)
