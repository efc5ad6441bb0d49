"""`history`, the kept versions of a calibration file, and going back to one with `adopt`, on
the simulated cell served in a thread: each save keeps the version before it; every version
is verified (a corrupted one says why); adopting an old version makes it the current file
again (its payload, a new checksum) and keeps the one it replaced."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from omnisort_hw.config.service import ServiceConfig
from omnisort_hw.pipeline.replies import HistoryReply
from omnisort_hw.service.client import Client
from omnisort_hw.service.server import Service, start_in_thread
from omnisort_hw.wire_records import from_wire, to_wire

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

TOKEN = "history-test-token-3456"


def _payload(path: Path) -> dict:
    record = json.loads(path.read_text())
    return {k: v for k, v in record.items() if k not in ("storage", "checksum")}


def test_versions_are_listed_verified_and_restored(tmp_path: Path) -> None:
    from tests.service.sim_cell import calibrated_sim_cell

    cell = calibrated_sim_cell(tmp_path, width=320)
    state = tmp_path / "state"
    first = _payload(state / "system.json")
    second = {**first, "method": "joint"}
    second["laser_plane"] = {**first["laser_plane"], "distance_mm": 1121.5}
    cell.store.save("system", second)
    running = start_in_thread(Service(cell, ServiceConfig(port=0, token=TOKEN)))
    try:
        with Client(running.host, running.port, token=TOKEN, timeout_s=120) as op:
            listed = op.execute("history")
            oldest = listed["versions"][-1]["path"]
            restored = op.execute("adopt", {"system": oldest})
            after = op.execute("history", {"kind": "system"})
            # A kept version that was damaged is listed with why, not its figures.
            damaged = Path(after["versions"][1]["path"])
            damaged.write_text(damaged.read_text().replace("1121.5", "1122.5"))
            checked = op.execute("history")
            cameras = op.execute("history", {"kind": "camera"})
            bad = op.call("history", {"kind": "laser"})
        with Client(running.host, running.port, timeout_s=30) as anyone:
            denied = anyone.call("history")
    finally:
        running.stop()
    for reply in (listed, after, checked, cameras):  # the record holds it all, problems too
        assert to_wire(from_wire(HistoryReply, reply)) == reply

    versions = listed["versions"]
    assert [v["current"] for v in versions] == [True, False]
    assert versions[0]["summary"].startswith("method joint, laser at 1121.50 mm")
    assert "laser at 1120.00 mm" not in versions[0]["summary"]
    assert versions[1]["summary"].startswith("method truth")
    assert restored["adopted"]["system"]["from"] == oldest
    assert _payload(state / "system.json") == first  # the old version is current again
    assert [v["current"] for v in after["versions"]] == [True, False, False]
    assert after["versions"][0]["checksum"] == restored["adopted"]["system"]["checksum"]
    assert after["versions"][1]["summary"].startswith("method joint")  # the one it replaced
    assert "problem" in checked["versions"][1] and "summary" not in checked["versions"][1]
    assert "checksum" in checked["versions"][1]["problem"]
    assert cameras["kind"] == "camera" and cameras["versions"][0]["current"]
    assert cameras["versions"][0]["summary"]
    assert bad["error"]["code"] == "bad_argument" and bad["error"]["field"] == "kind"
    assert denied["error"]["code"] == "unauthorized"
