"""A recording stand-in for the UR controller at the `URLink` boundary (no controller runs here).

It implements `drivers.ur_rtde_adapter.URLink` in the controller's units (rad, m, rotvec rad),
records every call in `calls` as `(name, args)`, and can inject the faults a real cell shows:
`drop()` (network cable pulled), `protective_stop()` / `emergency_stop()` (at once or after a
number of polls of a running move), `hang_moves` (a move never finishes), `refuse_reconnect`,
and a robot that is powered off (`robot_mode_value = 3`). A move "runs" for `move_polls` calls
of `is_moving()` and then lands exactly on its target.
"""

from __future__ import annotations

from typing import Any

from drivers.errors import DeviceDisconnectedError, DeviceNotFoundError
from drivers.ur_rtde_adapter import IOKind

HOME_Q = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
HOME_POSE = [0.3, -0.1, 0.4, 0.0, 3.14159, 0.0]


class RecordingURLink:
    """Implements `URLink`; `calls` lists what the driver sent, in order."""

    def __init__(self, *, move_polls: int = 2) -> None:
        self.calls: list[tuple[str, tuple[Any, ...]]] = []
        self.q = list(HOME_Q)
        self.pose = list(HOME_POSE)
        self.connected = False
        self.reachable = True
        self.refuse_reconnect = False
        self.robot_mode_value = 7
        self.safety_mode_value = 1
        self.move_polls = move_polls
        self.hang_moves = False
        self.stop_after_polls: tuple[int, int] | None = None
        self.drop_after_polls: int | None = None
        self.outputs: dict[tuple[str, int], bool] = {}
        self.inputs: dict[tuple[str, int], bool] = {}
        self._moving = 0
        self._polls = 0
        self._target: tuple[str, list[float]] | None = None

    # -- fault injection -------------------------------------------------------------------
    def drop(self) -> None:
        """The connection drops (cable pulled)."""
        self.connected = False

    def protective_stop(self) -> None:
        self.safety_mode_value = 3
        self._moving = 0

    def emergency_stop(self) -> None:
        self.safety_mode_value = 7
        self.robot_mode_value = 3
        self._moving = 0

    # -- helpers ---------------------------------------------------------------------------
    def _rec(self, name: str, *args: Any) -> None:
        self.calls.append((name, args))

    def _need(self) -> None:
        if not self.connected:
            raise DeviceDisconnectedError("stand-in: connection is down", device="standin")

    def names(self) -> list[str]:
        """Names of the recorded calls."""
        return [c[0] for c in self.calls]

    def motion_calls(self) -> list[tuple[str, tuple[Any, ...]]]:
        return [c for c in self.calls if c[0] in ("move_j", "move_l")]

    # -- URLink ----------------------------------------------------------------------------
    def open(self, host: str, timeout_s: float) -> None:
        self._rec("open", host, timeout_s)
        if not self.reachable:
            raise DeviceNotFoundError(f"stand-in: nothing at {host}", device=host)
        self.connected = True

    def close(self) -> None:
        self._rec("close")
        self.connected = False

    def is_connected(self) -> bool:
        return self.connected

    def reconnect(self, timeout_s: float) -> None:
        self._rec("reconnect", timeout_s)
        if self.refuse_reconnect or not self.reachable:
            raise DeviceDisconnectedError("stand-in: reconnect refused", device="standin")
        self.connected = True

    def actual_q(self) -> list[float]:
        self._need()
        return list(self.q)

    def actual_qd(self) -> list[float]:
        self._need()
        return [0.1 if self._moving > 0 else 0.0] * 6

    def actual_tcp_pose(self) -> list[float]:
        self._need()
        return list(self.pose)

    def robot_mode(self) -> int:
        self._need()
        return self.robot_mode_value

    def safety_mode(self) -> int:
        self._need()
        return self.safety_mode_value

    def move_j(self, q: list[float], speed: float, accel: float) -> None:
        self._rec("move_j", list(q), speed, accel)
        self._need()
        self._target = ("q", list(q))
        self._moving = self.move_polls
        self._polls = 0

    def move_l(self, pose: list[float], speed: float, accel: float) -> None:
        self._rec("move_l", list(pose), speed, accel)
        self._need()
        self._target = ("pose", list(pose))
        self._moving = self.move_polls
        self._polls = 0

    def move_path(self, rows: list[tuple[str, list[float]]]) -> None:
        self._rec("move_path", [(kind, list(row)) for kind, row in rows])
        self._need()
        kind, row = rows[-1]
        self._target = ("pose" if kind == "linear" else "q", list(row[:6]))
        self._moving = self.move_polls
        self._polls = 0

    def is_moving(self) -> bool:
        self._need()
        self._polls += 1
        if self.stop_after_polls is not None and self._polls >= self.stop_after_polls[0]:
            if self.stop_after_polls[1] == 7:
                self.emergency_stop()
            else:
                self.protective_stop()
            return False
        if self.drop_after_polls is not None and self._polls >= self.drop_after_polls:
            self.drop()
            self._need()
        if self.hang_moves and self._target is not None:
            return True
        if self._moving > 0:
            self._moving -= 1
            if self._moving == 0 and self._target is not None:
                kind, value = self._target
                if kind == "q":
                    self.q = list(value)
                else:
                    self.pose = list(value)
                self._target = None
            return self._moving > 0
        return False

    def stop_j(self, decel: float) -> None:
        self._rec("stop_j", decel)
        self._need()
        self._moving = 0
        self._target = None

    def stop_l(self, decel: float) -> None:
        self._rec("stop_l", decel)
        self._need()
        self._moving = 0
        self._target = None

    def set_output(self, kind: IOKind, pin: int, value: bool) -> None:
        self._rec("set_output", kind, pin, value)
        self._need()
        self.outputs[(kind, pin)] = value

    def output(self, kind: IOKind, pin: int) -> bool:
        self._need()
        return self.outputs.get((kind, pin), False)

    def input(self, kind: IOKind, pin: int) -> bool:
        self._need()
        return self.inputs.get((kind, pin), False)
