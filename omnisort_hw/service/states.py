"""The service's explicit state machine and the record of the one job running."""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any, TypedDict

log = logging.getLogger("omnisort.service")


class State(StrEnum):
    """The service's explicit state. `moving` is a single `move` command."""

    IDLE = "idle"
    CALIBRATING = "calibrating"
    MAPPING = "mapping"
    SORTING = "sorting"
    MOVING = "moving"
    STOPPED = "stopped"
    FAULT = "fault"


RESTING = frozenset({State.IDLE, State.STOPPED})


@dataclass(frozen=True)
class Transition:
    """One state change, as logged and reported by `status`."""

    at: str
    old: str
    new: str
    reason: str


class StateMachine:
    """The current state with its reason; every change is logged and passed to `on_change`."""

    def __init__(self, on_change: Callable[[Transition], None] | None = None) -> None:
        self._lock = threading.Lock()
        self._state = State.IDLE
        self._reason = "started"
        self._since = time.time()
        self._history: deque[Transition] = deque(maxlen=50)
        self._on_change = on_change

    @property
    def state(self) -> State:
        return self._state

    @property
    def reason(self) -> str:
        return self._reason

    def set(self, new: State, reason: str) -> Transition:
        with self._lock:
            old = self._state
            self._state, self._reason, self._since = new, reason, time.time()
            tr = Transition(_iso(self._since), old.value, new.value, reason)
            self._history.append(tr)
        log.info("state %s -> %s (%s)", tr.old, tr.new, reason)
        if self._on_change is not None:
            try:
                self._on_change(tr)
            except Exception:
                log.exception("state change hook failed")
        return tr

    def snapshot(self) -> StateSnapshot:
        with self._lock:
            return {
                "state": self._state.value,
                "reason": self._reason,
                "since": _iso(self._since),
                "transitions": [t.__dict__ for t in list(self._history)[-10:]],
            }


class StateSnapshot(TypedDict):
    """The state (idle, calibrating, mapping, moving, sorting, stopped or fault), why, since
    when (ISO 8601, UTC) and the last ten transitions."""

    state: str
    reason: str
    since: str
    transitions: list[dict[str, Any]]


def _iso(wall: float) -> str:
    return datetime.fromtimestamp(wall, UTC).isoformat(timespec="milliseconds")


class JobRecord(TypedDict):
    """The running job in `status`: its command and request, how long it has run, how long the
    last such job took on this cell (None: none has yet), whether a stop was asked, and its
    progress events."""

    cmd: str
    request_id: int | str | None
    running_s: float
    expected_s: float | None
    cancelled: bool
    progress: list[dict[str, Any]]


@dataclass
class Job:
    """The one long command running now."""

    cmd: str
    request_id: int | str | None
    state: State
    cancel: threading.Event = field(default_factory=threading.Event)
    started: float = field(default_factory=time.monotonic)
    stopped_by: str | None = None
    progress: list[dict[str, Any]] = field(default_factory=list)
    expected_s: float | None = None  # the last such job's duration on this cell, if any

    def report(self, event: dict[str, Any]) -> None:
        """Progress from the running job (e.g. each cube sorted); `status` shows it."""
        self.progress.append(dict(event))
        del self.progress[:-50]

    def describe(self) -> JobRecord:
        return {
            "cmd": self.cmd,
            "request_id": self.request_id,
            "running_s": round(time.monotonic() - self.started, 3),
            "expected_s": self.expected_s,
            "cancelled": self.cancel.is_set(),
            "progress": list(self.progress),
        }
