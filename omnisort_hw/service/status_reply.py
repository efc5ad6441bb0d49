"""The `status` reply, typed: the service's state machine and job (`ServiceStatus`), the
cell's devices and calibration (`cell.status_reply.CellStatus`), and whether motion is allowed.
What the operator interface and `omnisort ctl status` read. (No postponed annotations: a
TypedDict reads `NotRequired` when its class is made.)"""

from typing import TypedDict

from omnisort_hw.cell.status_reply import CellStatus
from omnisort_hw.core.records import Record
from omnisort_hw.service.states import JobRecord, StateSnapshot


class LastError(TypedDict):
    """The last error the service answered: its code, message and how long ago (s)."""

    code: str
    message: str
    age_s: float


class ServiceRecord(TypedDict):
    """The service itself: version, process, address, token rule, clients, uptime, and its
    counters; every error answered is counted by its code, and the last one is kept, so a
    rising count can be told apart (a page's refused detections, a client's bad requests)."""

    version: str
    pid: int
    host: str
    port: int
    token_required: bool
    clients: int
    uptime_s: float
    requests: int
    errors: int
    connections: int
    slow_clients_dropped: int
    errors_by_code: dict[str, int]
    last_error: LastError | None


class ServiceStatus(StateSnapshot):
    """The state machine's snapshot (state, reason, since, the last ten transitions), the job
    running, the last run and the service itself."""

    job: JobRecord | None  # the running job
    last_run: Record | None  # the journal's last job
    service: ServiceRecord


class StatusReply(ServiceStatus, CellStatus):
    motion_allowed: bool  # calibration usable and the state not fault
