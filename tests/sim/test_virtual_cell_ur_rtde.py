"""The unmodified ur-rtde client against `omnisort sim virtual-cell`, in its own process.

Joints within 0.01 deg after moveJ and the TCP within 0.1 mm after moveL (what a controller
does: the move ends on its target), digital outputs read back, a protective stop refuses
commands until unlocked and the control script re-uploaded.
"""

from __future__ import annotations

import pytest

from tests.sim.virtual_cell_fixture import run_client, virtual_cell

pytest.importorskip("rtde_control", reason="needs ur-rtde")
pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]


@pytest.fixture(scope="module")
def vc():
    with virtual_cell(width=128) as cell:
        yield cell


def test_plain_ur_rtde_client_behaves_as_on_a_controller(vc) -> None:
    out = run_client("tests.sim.ur_rtde_client", vc.host)
    checks = {
        "polyscope 5.x": out["polyscope"].startswith("5."),
        "robot mode": out["robotmode"] == "Robotmode: RUNNING",
        "moveJ within 0.01 deg": out["movej_ok"] and out["movej_err_deg"] < 0.01,
        "moveL within 0.1 mm": out["movel_ok"] and out["movel_err_mm"] < 0.1,
        "moveL orientation": out["movel_rot_err"] < 1e-6,
        "not stopped before": out["protective_before"] is False,
        "digital output": out["set_do_ok"] and out["do_bit"] and out["do_cleared"],
        "async moveJ running": out["async_ok"] and out["async_running"],
        "protective stop seen": out["protective_seen"] and out["safety_mode"] == 3,
        "program stopped": out["program_running_after_stop"] is False,
        "moveJ refused in stop": out["movej_refused_in_stop"],
        "unlock and re-upload": out["unlocked"] and out["reupload_ok"],
        "moveJ after": out["movej_after_ok"] and out["movej_after_err_deg"] < 0.01,
    }
    assert all(checks.values()), ([k for k, ok in checks.items() if not ok], out)
    status = vc.control("status")
    assert status["safety_mode"] == "NORMAL" and not status["program_running"]


def test_dashboard_answers_like_polyscope(vc) -> None:
    import socket

    with socket.create_connection((vc.host, 29999), timeout=5) as s:
        f = s.makefile("rwb")
        assert f.readline().startswith(b"Connected: Universal Robots Dashboard Server")
        for line, want in (
            (b"robotmode\n", b"Robotmode: RUNNING"),
            (b"safetystatus\n", b"Safetystatus: NORMAL"),
            (b"is in remote control\n", b"true"),
            (b"get serial number\n", b"20235500001"),
            (b"bogus\n", b"could not understand: 'bogus'"),
        ):
            f.write(line)
            f.flush()
            assert f.readline().strip() == want
