"""The virtual cell over the real protocols: ur-rtde latency and accuracy, fault detection
times of the real UR driver, what the camera stream's JPEG costs the laser stripe, and the
end-to-end sort through `omnisort serve` with the real drivers (time per pick).

* RTDE round trip: `setStandardDigitalOut` (an RTDE input package) until the output stream
  reports the bit (`actual_digital_output_bits`), measured with the real ur-rtde client.
* command handshake: `moveJ` to the current joints (async): command register -> done -> clear.
* joint / TCP error after `moveJ` / `moveL` (what a controller reaches: the target).
* stripe: laser stripe points (`core.laser_stripe`) of one 960 px frame from the lossless
  `/frame.png` against the same frame through the MJPEG stream at each quality.
"""

from __future__ import annotations

import statistics
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np

from sim_backend.virtual_cell.launcher import VirtualCellProcess


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q))


def _rtde_figures(host: str) -> dict[str, Any]:
    import rtde_control
    import rtde_io
    import rtde_receive

    rcv = rtde_receive.RTDEReceiveInterface(host)
    ctl = rtde_control.RTDEControlInterface(host)
    io = rtde_io.RTDEIOInterface(host)
    trips = []
    for i in range(200):
        level = i % 2 == 0
        t0 = time.perf_counter()
        io.setStandardDigitalOut(5, level)
        while ((rcv.getActualDigitalOutputBits() >> 5) & 1) != level:
            if time.perf_counter() - t0 > 1.0:
                raise RuntimeError("digital output not reported within 1 s")
        trips.append((time.perf_counter() - t0) * 1000.0)
    hand = []
    for _ in range(50):
        q = rcv.getActualQ()
        t0 = time.perf_counter()
        ctl.moveJ(q, 1.0, 1.0, True)
        hand.append((time.perf_counter() - t0) * 1000.0)
    rng = np.random.default_rng(3)
    q0 = np.asarray(rcv.getActualQ())
    j_err, l_err = [], []
    for _ in range(5):
        target = q0 + np.deg2rad(rng.uniform(-10, 10, 6))
        ctl.moveJ(list(target), 1.5, 3.0)
        time.sleep(0.01)
        j_err.append(float(np.max(np.abs(np.rad2deg(np.asarray(rcv.getActualQ()) - target)))))
        goal = np.asarray(rcv.getActualTCPPose())
        goal[:3] += rng.uniform(-0.05, 0.05, 3)
        ctl.moveL(list(goal), 0.5, 2.0)
        time.sleep(0.01)
        l_err.append(float(np.linalg.norm(np.asarray(rcv.getActualTCPPose())[:3] - goal[:3])))
    ctl.moveJ(list(q0), 1.5, 3.0)
    ctl.stopScript()
    for iface in (ctl, io, rcv):
        iface.disconnect()
    return {
        "rtde_round_trip_median_ms": round(statistics.median(trips), 2),
        "rtde_round_trip_p99_ms": round(_pct(trips, 99), 2),
        "command_handshake_median_ms": round(statistics.median(hand), 2),
        "movej_joint_error_max_deg": float(f"{max(j_err):.2e}"),
        "movel_tcp_error_max_mm": float(f"{max(l_err) * 1000.0:.2e}"),
    }


def _fault_during_move(arm: Any, fault: Any) -> tuple[float, str]:
    """Start a slow joint move, inject `fault()` 0.5 s in; seconds until the move's typed
    error, and its code."""
    from drivers.errors import DeviceError

    box: dict[str, Any] = {}

    def move() -> None:
        try:
            arm.move_joints(arm.joint_positions() + np.array([30.0, 0, 0, 0, 0, 0]), 20.0)
        except DeviceError as exc:
            box["t"], box["code"] = time.monotonic(), exc.code

    th = threading.Thread(target=move)
    th.start()
    time.sleep(0.5)
    t0 = time.monotonic()
    fault()
    th.join(15)
    return round(box["t"] - t0, 3), box["code"]


def _fault_figures(vc: VirtualCellProcess) -> dict[str, Any]:
    from drivers.errors import DeviceError
    from drivers.ur_arm import URArm, URArmConfig

    out: dict[str, Any] = {}
    arm = URArm(URArmConfig(host=vc.host, poll_period_s=0.01))
    t0 = time.monotonic()
    arm.connect()
    out["ur_driver_connect_s"] = round(time.monotonic() - t0, 2)
    seconds, _ = _fault_during_move(arm, lambda: vc.control("protective_stop"))
    out["protective_stop_to_safety_stop_s"] = seconds
    time.sleep(0.3)
    vc.dashboard("unlock protective stop")
    vc.control("stall", what="arm", seconds=3.0)
    t_stall = time.monotonic()
    try:
        while time.monotonic() - t_stall < 5.0:
            arm.joint_positions()
            time.sleep(0.01)
    except DeviceError as exc:
        out["stall_to_error_s"] = round(time.monotonic() - t_stall, 3)
        out["stall_error"] = exc.code
    time.sleep(3.0)
    arm.close()
    return out


def _stripe_figures(host: str) -> dict[str, Any]:
    import cv2

    from omnisort_hw.core.laser_stripe import laser_stripe_points

    def read(url: str) -> bytes:
        with urllib.request.urlopen(url, timeout=60) as r:
            return r.read()

    from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig

    with ModbusLaser(ModbusLaserConfig(host=host, tcp_port=5020)) as sw:
        sw.on()
        png = read(f"http://{host}:8080/frame.png")
        ref = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
        ref_pts = laser_stripe_points(ref)
        out: dict[str, Any] = {
            "stripe_points_lossless": len(ref_pts),
            "frame_png_kb": len(png) // 1024,
        }
        for label, query in (
            ("q80", "quality=80"),
            ("q95", "quality=95"),
            ("q100_444", "quality=100&sampling=444"),
        ):
            cap = cv2.VideoCapture(f"http://{host}:8080/stream.mjpg?{query}", cv2.CAP_FFMPEG)
            ok, img = cap.read()
            cap.release()
            if not ok:
                raise RuntimeError(f"stream {query} gave no frame")
            pts = laser_stripe_points(img)
            d = np.linalg.norm(pts[:, None, :] - ref_pts[None], axis=2).min(axis=1)
            out[f"stripe_{label}_points"] = len(pts)
            out[f"stripe_{label}_median_px"] = round(float(np.median(d)), 3)
            out[f"stripe_{label}_p95_px"] = round(float(np.percentile(d, 95)), 3)
            out[f"stripe_{label}_image_max_abs_diff"] = int(np.abs(img.astype(int) - ref).max())
        sw.off()
    return out


def run(shared: Path) -> dict[str, Any]:
    figures: dict[str, Any] = {}
    with VirtualCellProcess("sorting", width=960, unlock_delay_s=0.2) as vc:
        figures.update(_rtde_figures(vc.host))
        figures.update(_fault_figures(vc))
        figures.update(_stripe_figures(vc.host))
    with VirtualCellProcess("sorting", width=128) as doomed:
        from drivers.ur_arm import URArm, URArmConfig

        arm = URArm(URArmConfig(host=doomed.host, poll_period_s=0.01, reconnect_attempts=1))
        arm.connect()
        seconds, code = _fault_during_move(arm, doomed.kill)
        figures["killed_to_error_s"] = seconds
        figures["killed_error"] = code
        arm.close()
    from omnisort_hw.service.virtual_cell_demo import run as run_demo

    with tempfile.TemporaryDirectory() as tmp:
        summary = run_demo(Path(tmp) / "demo", 960)
    figures["sort_cubes_in_their_bin"] = summary["cubes_in_their_bin"]
    figures["sort_cubes"] = summary["cubes"]
    figures["sort_collisions"] = len(summary["truth"]["collisions"])
    figures["sort_seconds_per_pick"] = summary.get("seconds_per_pick")
    figures["service_steps_s"] = {s["step"]: s["seconds"] for s in summary["steps"]}
    return figures
