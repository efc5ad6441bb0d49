"""The `status` reply, typed: the service's state machine and job (`ServiceStatus`), the
cell's devices and calibration (`cell.status_reply.CellStatus`), and whether motion is allowed.
What the operator interface and `omnisort ctl status` read. (No postponed annotations: a
TypedDict reads `NotRequired` when its class is made.)"""

from omnisort_hw.cell.status_reply import CellStatus
from omnisort_hw.core.records import Record
from omnisort_hw.service.states import StateSnapshot


class ServiceStatus(StateSnapshot):
    """The state machine's snapshot (state, reason, since, the last ten transitions), the job
    running, the last run and the service itself."""

    job: Record | None  # the running job: command, request id, running time, progress
    last_run: Record | None  # the journal's last job
    service: Record  # version, pid, address, token rule, clients, uptime, counters


class StatusReply(ServiceStatus, CellStatus):
    motion_allowed: bool  # calibration usable and the state not fault
