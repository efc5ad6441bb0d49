"""The service over real loopback TCP with in-memory devices: commands, states, concurrency."""

from __future__ import annotations

import base64
import threading
import time
from pathlib import Path

import cv2
import pytest

from omnisort_hw.runlog import entity_paths
from tests.service.conftest import TOKEN, Harness

pytestmark = pytest.mark.timeout(60)


def test_status_reports_state_devices_and_calibration(service: Harness) -> None:
    with service.client() as c:
        r = c.call("status")
    assert r["ok"], r
    res = r["result"]
    assert res["state"] == "idle"
    assert res["job"] is None
    assert res["motion_allowed"] is True
    assert res["calibration"]["files"]["camera"]["health"] == "ok"
    assert res["devices"]["camera"]["serial"] == "FAKE-CAM-1"
    assert res["devices"]["arm"]["safety"]["ok"] is True
    assert res["service"]["token_required"] is False
    assert res["rrd"].endswith(".rrd")


def test_errors_are_counted_by_code_with_the_last_one_shown(service: Harness) -> None:
    """A rising error count says what it is made of: each code's count and the last error."""
    from omnisort_hw.service.status_reading import status_rows

    with service.client() as c:
        before = c.call("status")["result"]["service"]
        assert not c.call("nonsense")["ok"]
        assert not c.call("capture", {"exposure_ms": "x"})["ok"]
        st = c.call("status")["result"]
    svc = st["service"]
    assert svc["errors"] == before["errors"] + 2
    by_code = before["errors_by_code"]
    for code in ("unknown_command", "bad_argument"):
        assert svc["errors_by_code"][code] == by_code.get(code, 0) + 1, svc["errors_by_code"]
    last = svc["last_error"]
    assert last["code"] == "bad_argument" and "exposure_ms" in last["message"], last
    assert 0.0 <= last["age_s"] < 60.0
    shown = [v for _, v in status_rows(st) if v.startswith("errors: ")]
    assert shown and "unknown_command 1" in shown[0] and "last, " in shown[0], shown


def test_capture_as_path_and_base64(service: Harness) -> None:
    import cv2
    import numpy as np

    with service.client() as c:
        r = c.call("capture", {"laser": True})
        assert r["ok"], r
        img = cv2.imread(r["result"]["path"])
        assert img.shape == (48, 64, 3)
        r = c.call("capture", {"encoding": "base64", "format": "png"})
        data = base64.b64decode(r["result"]["base64"])
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (48, 64, 3)
        assert c.call("laser")["result"] == {"on": True}
        assert c.call("laser", {"on": False})["result"] == {"on": False}
    assert "laser on" in service.journal.events


def test_one_motion_at_a_time_and_status_meanwhile(make_service) -> None:
    h = make_service(move_seconds=1.5)
    with h.client() as a, h.client() as b:
        rid = a.send("move", {"joints_deg": [10, 0, 0, 0, 0, 0]})
        deadline = time.monotonic() + 5
        while not h.devices.arm.moving.is_set():
            assert time.monotonic() < deadline
            time.sleep(0.01)
        t0 = time.perf_counter()
        st = b.call("status")
        assert time.perf_counter() - t0 < 0.5
        assert st["result"]["state"] == "moving"
        assert st["result"]["job"]["cmd"] == "move"
        second = b.call("move", {"joints_deg": [1, 0, 0, 0, 0, 0]})
        assert second["error"]["code"] == "busy"
        assert "one motion" in second["error"]["message"]
        for cmd in ("sort", "calibrate"):
            args = {"what": "extrinsics"} if cmd == "calibrate" else None
            assert b.call(cmd, args)["error"]["code"] == "busy"
        assert b.call("laser", {"on": True})["error"]["code"] == "busy"
        # Same connection: status is answered before the move's reply.
        assert a.call("status")["result"]["state"] == "moving"
        done = a.read_reply(timeout_s=10)
        assert done["id"] == rid and done["ok"], done
        assert done["result"]["joints_deg"][0] == 10.0
        assert b.call("status")["result"]["state"] == "idle"


def test_stop_interrupts_a_motion(make_service) -> None:
    h = make_service(move_seconds=20.0)
    with h.client() as a, h.client() as b:
        rid = a.send("move", {"pose": [300, 0, 300, 0, 0, 0], "speed_mm_s": 100})
        deadline = time.monotonic() + 5
        while not h.devices.arm.moving.is_set():
            assert time.monotonic() < deadline
            time.sleep(0.01)
        r = b.call("stop")
        assert r["ok"] and r["result"]["stopped_job"] == "move"
        moved = a.read_reply(timeout_s=5)
        assert moved["id"] == rid and moved["error"]["code"] == "stopped"
        assert b.call("status")["result"]["state"] == "stopped"
        h.devices.arm.move_seconds = 0.05
        again = b.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]})
        assert again["ok"], again
        assert b.call("status")["result"]["state"] == "idle"
    assert "arm move_linear interrupted" in h.journal.events


def test_estop_latches_fault_until_reset(service: Harness) -> None:
    with service.client() as c:
        c.call("laser", {"on": True})
        r = c.call("estop")
        assert r["ok"] and r["result"]["state"] == "fault"
        assert c.call("laser")["result"]["on"] is False
        refused = c.call("move", {"joints_deg": [1, 0, 0, 0, 0, 0]})
        assert refused["error"]["code"] == "motion_refused"
        assert "reset" in refused["error"]["message"]
        service.devices.arm.protective_stop = True
        r = c.call("reset")
        assert r["error"]["code"] == "device_error"
        assert r["error"]["device_code"] == "safety_stop"
        service.devices.arm.protective_stop = False
        assert c.call("reset")["result"]["state"] == "idle"
        assert c.call("move", {"joints_deg": [1, 0, 0, 0, 0, 0]})["ok"]


def test_device_error_during_a_job_is_a_fault(service: Harness) -> None:
    with service.client() as c:
        service.devices.arm.protective_stop = True
        r = c.call("move", {"joints_deg": [1, 0, 0, 0, 0, 0]})
        assert r["error"]["code"] == "device_error"
        assert r["error"]["device_code"] == "safety_stop"
        st = c.call("status")["result"]
        assert st["state"] == "fault" and st["motion_allowed"] is False


def test_limits_are_refused_by_the_driver(service: Harness) -> None:
    with service.client() as c:
        eye = [[1, 0, 0, 5000], [0, 1, 0, 0], [0, 0, 1, 300], [0, 0, 0, 1]]
        r = c.call("move", {"matrix": eye})
        assert r["error"]["code"] == "motion_refused"
        assert "workspace" in r["error"]["message"]
        assert c.call("status")["result"]["state"] == "idle"


def test_missing_or_corrupt_calibration_blocks_motion(make_service) -> None:
    h = make_service(calibrated=False)
    with h.client() as c:
        r = c.call("move", {"joints_deg": [1, 0, 0, 0, 0, 0]})
        assert r["error"]["code"] == "motion_refused"
        assert "camera missing" in r["error"]["message"]
        st = c.call("status")["result"]
        assert st["motion_allowed"] is False
        assert st["calibration"]["files"]["system"]["health"] == "missing"
        assert st["state"] == "idle"
    from tests.service.fakes import write_calibration

    write_calibration(h.cell.store)
    path = h.cell.store.path("system")
    path.write_text(path.read_text().replace('"method"', '"methdo"'))
    with h.client() as c:
        r = c.call("move", {"joints_deg": [1, 0, 0, 0, 0, 0]})
        assert r["error"]["code"] == "motion_refused"
        assert "system corrupt" in r["error"]["message"]
        assert "checksum mismatch" in r["error"]["message"]


@pytest.mark.parametrize(
    ("cmd", "args", "component"),
    [
        ("register_robot", None, "robot registration"),
        ("locate", None, "colour-blob"),
        ("sort", {"max_objects": 3}, "sorting pipeline"),
    ],
)
def test_pipeline_commands_say_what_is_missing(service: Harness, cmd, args, component) -> None:
    with service.client() as c:
        r = c.call(cmd, args)
        assert r["error"]["code"] == "not_available", r
        assert component in r["error"]["message"]
        assert c.call("status")["result"]["state"] == "idle"


def test_token_rules(make_service) -> None:
    h = make_service(token=TOKEN)
    with h.client() as anon, h.client(token="wrong-token-wrong-token") as wrong:
        assert anon.call("status")["ok"]
        assert anon.call("stop")["ok"]
        assert anon.call("estop")["ok"]
        for cmd, args in [
            ("capture", None),
            ("laser", {"on": True}),
            ("move", {"joints_deg": [0] * 6}),
            ("sort", None),
            ("reset", None),
            ("shutdown", None),
        ]:
            r = anon.call(cmd, args)
            assert r["error"]["code"] == "unauthorized", r
            assert "token" in r["error"]["message"]
            assert wrong.call(cmd, args)["error"]["code"] == "unauthorized"
    with h.client(token=TOKEN) as ok:
        assert ok.call("reset")["ok"]
        assert ok.call("capture")["ok"]
        st = ok.call("status")["result"]
        assert st["service"]["token_required"] is True


def test_non_loopback_needs_a_token(tmp_path) -> None:
    from omnisort_hw.config.service import ServiceConfig
    from omnisort_hw.errors import ConfigError
    from omnisort_hw.service.server import Service
    from tests.service.fakes import make_cell

    cell, _, _ = make_cell(tmp_path / "s")
    with pytest.raises(ConfigError, match="without a token"):
        Service(cell, ServiceConfig(host="0.0.0.0", port=0, token=None))
    cell.close()


def test_shutdown_makes_the_cell_safe_and_flushes_the_log(make_service) -> None:
    h = make_service(move_seconds=20.0)
    with h.client() as c:
        c.call("laser", {"on": True})
        c.call("capture")
        c.send("move", {"joints_deg": [3, 0, 0, 0, 0, 0]})
        while not h.devices.arm.moving.is_set():
            time.sleep(0.01)
        assert c.call("shutdown")["result"] == {"shutting_down": True}
    h.running.thread.join(20)
    assert not h.running.thread.is_alive()
    assert h.running.exit_code == [0]
    ev = h.journal.events
    assert "arm stop" in ev and "laser off" in ev and "arm close" in ev
    assert ev.index("laser off") > ev.index("laser on")
    paths = entity_paths(h.cell.runlog_path or "")
    assert {"/service/state", "/camera/raw", "/arm/command", "/laser/state"} <= paths
    assert {"/arm/planned/q1", "/arm/executed/q6", "/arm/executed/tcp"} <= paths


def test_many_connections_are_limited(make_service) -> None:
    h = make_service(max_clients=3)
    clients = [h.client() for _ in range(3)]
    try:
        for c in clients:
            assert c.call("status")["ok"]
        extra = h.client()
        r = extra.read_reply(timeout_s=5)
        assert r["error"]["code"] == "busy" and "too many clients" in r["error"]["message"]
        extra.close()
    finally:
        for c in clients:
            c.close()
    deadline = time.monotonic() + 5
    while True:
        with h.client() as c:
            r = c.call("status")
        if r["ok"] or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    assert r["ok"]


def test_concurrent_status_clients_all_answered(make_service) -> None:
    h = make_service(move_seconds=2.0)
    errors: list[str] = []

    def poll() -> None:
        try:
            with h.client(timeout_s=5) as c:
                for _ in range(20):
                    r = c.call("status")
                    if not r["ok"]:
                        errors.append(str(r))
        except Exception as exc:
            errors.append(repr(exc))

    with h.client() as mover:
        mover.send("move", {"joints_deg": [2, 0, 0, 0, 0, 0]})
        threads = [threading.Thread(target=poll) for _ in range(10)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        assert mover.read_reply(timeout_s=10)["ok"]
    assert errors == []


def test_stop_right_after_a_move_request_leaves_the_arm_still(make_service) -> None:
    """However stop and the job's start interleave, the arm ends up not moving."""
    h = make_service(move_seconds=20.0)
    with h.client() as a, h.client() as b:
        for delay in (0.0, 0.001, 0.005, 0.02):
            rid = a.send("move", {"joints_deg": [4, 0, 0, 0, 0, 0]})
            deadline = time.monotonic() + 5
            while b.call("status")["result"]["job"] is None:
                assert time.monotonic() < deadline
            time.sleep(delay)
            assert b.call("stop")["ok"]
            reply = a.read_reply(timeout_s=5)
            assert reply["id"] == rid
            assert reply["error"]["code"] == "stopped", reply
            time.sleep(0.3)
            assert not h.devices.arm.moving.is_set()
            assert b.call("status")["result"]["job"] is None


def test_calibrate_intrinsics_errors_are_typed(service: Harness, tmp_path) -> None:
    with service.client() as c:
        args = {"what": "intrinsics", "folder": str(tmp_path / "none"), "square_mm": 20}
        r = c.call("calibrate", args)
        assert r["error"]["code"] == "bad_input" and "no such folder" in r["error"]["message"]
        (tmp_path / "imgs").mkdir()
        import cv2
        import numpy as np

        for i in range(3):
            cv2.imwrite(str(tmp_path / "imgs" / f"{i}.png"), np.full((60, 80, 3), 128, np.uint8))
        args["folder"] = str(tmp_path / "imgs")
        r = c.call("calibrate", args, timeout_s=60)
        assert r["error"]["code"] == "calibration_failed", r
        assert "at least" in r["error"]["message"]
        st = c.call("status")["result"]
        assert st["state"] == "idle"
        assert st["calibration"]["files"]["camera"]["health"] == "ok"


def test_extrinsics_and_map_need_their_inputs(service: Harness) -> None:
    with service.client() as c:
        r = c.call("calibrate", {"what": "extrinsics"})
        assert r["error"]["code"] == "bad_input" and "target: one of" in r["error"]["message"]
        # A wall target's scale is its measured separation: refused before any frame is taken.
        grabs = service.devices.camera._seq
        r = c.call("calibrate", {"what": "extrinsics", "target": "two-sided"})
        assert r["error"]["code"] == "bad_input" and "separation_mm" in r["error"]["message"], r
        r = c.call(
            "calibrate", {"what": "extrinsics", "target": "two-sided", "separation_mm": 1.2924}
        )
        assert r["error"]["code"] == "bad_input" and "looks like metres" in r["error"]["message"]
        assert service.devices.camera._seq == grabs
        r = c.call(
            "calibrate", {"what": "extrinsics", "target": "checkerboards", "separation_mm": 1292.4}
        )
        assert r["error"]["code"] == "bad_argument" and "separation_mm" in r["error"]["message"]
        # The in-memory cell's system.json is a stand-in without a camera rotation matrix.
        r = c.call("map")
        assert r["error"]["code"] == "bad_calibration_file", r
        assert "system.json" in r["error"]["message"]
        assert c.call("status")["result"]["state"] == "idle"


@pytest.mark.reference
def test_calibration_and_map_on_the_reference_images(make_service, reference_dir) -> None:
    """Intrinsics, then extrinsics from the two-sided target, then a laser map, all through
    the protocol on the third-party reference images."""
    h = make_service(calibrated=False)
    with h.client(timeout_s=300) as c:
        r = c.call(
            "calibrate",
            {"what": "intrinsics", "folder": str(reference_dir / "intrinsics"), "square_mm": 116},
        )
        assert r["ok"], r
        res = r["result"]
        assert res["images_used"] == 9 and res["rms_px"] < 0.3
        assert res["camera_serial"] == "FAKE-CAM-1"
        st = c.call("status")["result"]
        cam = st["calibration"]["files"]["camera"]
        assert cam["health"] == "ok" and cam["camera_serial"] == "FAKE-CAM-1"
        assert st["calibration"]["files"]["system"]["health"] == "missing"
        assert st["motion_allowed"] is False
        assert h.cell.store.camera_model().image_size == (1920, 1920)
        r = c.call(
            "calibrate",
            {
                "what": "extrinsics",
                "image": str(reference_dir / "two_sided_target.png"),
                "target": "two-sided",
                "separation_mm": 1292.4,
            },
        )
        assert r["ok"], r
        assert set(r["result"]["parameters"]) >= {"cam_roll_deg", "laser_distance_mm"}
        # The picture of what was detected and fitted lies beside system.json: the image's
        # height, a legend column beside it.
        picture = Path(r["result"]["overlay_png"])
        assert picture.parent == Path(r["result"]["path"]).parent
        shown = cv2.imread(str(picture))
        assert shown.shape[0] == 1920 and shown.shape[1] > 1920
        st = c.call("status")["result"]["calibration"]
        assert st["files"]["system"]["health"] == "ok" and st["motion_allowed"] is True
        assert st["robot_registered"] is False
        r = c.call("map", {"image": str(reference_dir / "mapping_cubes.jpg")})
        assert r["ok"], r
        assert r["result"]["points_on_plane"] > 100 and r["result"]["segments"]
        assert "overlay_png" not in r["result"]  # drawn only when asked: map stays fast
        r = c.call("map", {"image": str(reference_dir / "mapping_cubes.jpg"), "picture": True})
        drawn = cv2.imread(r["result"]["overlay_png"])
        assert drawn.shape[0] == 1920 and drawn.shape[1] > 2 * 1920  # image + top view
    h.running.stop()
    paths = entity_paths(h.cell.runlog_path or "")
    assert {"/extrinsics/image", "/map/points_S", "/map/image/laser"} <= paths
    assert {"/calibration/intrinsics/rms_px", "/calibration/intrinsics/parameters"} <= paths
    assert "/intrinsics/image" in paths
