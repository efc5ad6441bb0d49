"""State rules everywhere: in `fault` nothing is switched on (laser included), as no motion
starts; switching off stays allowed; `stopped` is not a latch, for the laser as for motion."""

from __future__ import annotations

import numpy as np
import pytest

from tests.service.conftest import Harness

pytestmark = pytest.mark.timeout(60)


def test_fault_refuses_the_laser_as_it_refuses_motion(service: Harness) -> None:
    with service.client() as c:
        assert c.call("estop")["result"]["state"] == "fault"
        n_on = service.journal.events.count("laser on")
        refused = [
            c.call("laser", {"on": True}),
            c.call("capture", {"laser": True}),
            c.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]}),
        ]
        off = c.call("laser", {"on": False})
        plain = c.call("capture")
        assert c.call("reset")["ok"]
        on = c.call("laser", {"on": True})
    for r in refused:
        assert r["error"]["code"] == "motion_refused", r
    assert "fault" in refused[0]["error"]["message"] and "reset" in refused[0]["error"]["message"]
    assert service.journal.events.count("laser on") == n_on + 1  # only the one after reset
    assert off["ok"] and off["result"]["on"] is False
    assert plain["ok"], plain
    assert on["ok"] and on["result"]["on"] is True


def test_the_guard_holds_inside_the_cell_too(service: Harness) -> None:
    """A switch-on already past the service's check is refused under the device lock."""
    with service.client() as c:
        c.call("estop")
    with pytest.raises(Exception, match="fault") as info:
        service.cell.set_laser(True)
    assert getattr(info.value, "code", None) == "motion_refused"
    assert service.devices.laser.state() is False


def test_stopped_is_not_a_latch_for_laser_or_motion(service: Harness) -> None:
    with service.client() as c:
        assert c.call("stop")["result"]["state"] == "stopped"
        assert c.call("laser", {"on": True})["ok"]
        assert c.call("move", {"joints_deg": [5, 0, 0, 0, 0, 0]})["ok"]


def test_a_gripper_that_may_hold_something_refuses_sort_until_confirmed(service: Harness) -> None:
    from omnisort_hw.core.pick_planning import SortConfig
    from omnisort_hw.pipeline.gripper_load import GripperLoadedError, resolve_before_sort
    from omnisort_hw.pipeline.sort import Sorter

    grip = service.devices.arm.gripper
    grip.close()  # closed, no sensor, no pick on record: it may hold anything
    sorter = Sorter(None, service.devices.arm, None, None, SortConfig())  # type: ignore[arg-type]
    with pytest.raises(GripperLoadedError, match="gripper_empty=true") as info:
        resolve_before_sort(sorter, service.cell.journal, np.eye(4))
    assert info.value.code == "gripper_loaded"
    service.cell.refresh_status()
    with service.client() as c:
        assert c.call("status")["result"]["gripper"]["load"] == "maybe"
        assert c.call("reset", {"gripper_empty": True})["ok"]
        service.cell.refresh_status()
        assert c.call("status")["result"]["gripper"]["load"] == "empty"
    assert grip.is_closed is False
    assert resolve_before_sort(sorter, service.cell.journal, np.eye(4)) is None
