"""The cell's part of the `status` reply, typed: its devices, calibration, run log, gripper and
drift watchdog, and how old the snapshot is. (No postponed annotations: a TypedDict reads
`NotRequired` when its class is made.)"""

from typing import NotRequired, TypedDict

from omnisort_hw.core.records import Record


class CellStatus(TypedDict):
    devices: dict[str, Record]  # camera, laser, arm: each its health and last reading
    calibration: Record  # the store's files, their health, and motion_allowed
    rrd: str | None  # the run log being written
    logging: Record
    gripper: Record  # its load: empty, held, maybe or unknown
    drift: Record  # the watchdog's last check and whether it refuses motion
    status_age_s: NotRequired[float]  # the snapshot's age (absent when read just now)
