"""The live picture: one thread asks the service for `view` every `period_s` while at least one
page shows it, whatever the number of pages, and keeps the last picture and the rate it came
at. A picture the service could not give (the camera busy with a measurement, the service
down) leaves the last one shown, with the reason."""

from __future__ import annotations

import collections
import threading
import time

from omnisort_hw.pipeline.replies import ViewReply
from omnisort_hw.pipeline.requests import ViewRequest
from omnisort_hw.ui.link import CellCommands, ClientError, CommandError, ServiceLink, call_of


class LiveFeed:
    """`picture`, `problem` and `fps` of the live view; `watch()`/`unwatch()` by each page."""

    def __init__(self, link: ServiceLink, period_s: float, width_px: int) -> None:
        self.link, self.period_s, self.width_px = link, period_s, width_px
        self.picture: ViewReply | None = None  # the last live picture
        self.problem: str | None = None
        self.received = 0  # pictures received since the start
        self._times: collections.deque[float] = collections.deque(maxlen=20)
        self._watchers = 0
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def watch(self) -> None:
        with self._lock:
            self._watchers += 1
            if self._thread is None:
                self._thread = threading.Thread(target=self._loop, name="ui-view", daemon=True)
                self._thread.start()
        self._wake.set()

    def unwatch(self) -> None:
        with self._lock:
            self._watchers = max(0, self._watchers - 1)

    @property
    def watchers(self) -> int:
        with self._lock:
            return self._watchers

    @property
    def fps(self) -> float | None:
        """Pictures per second over the last (up to) 20."""
        with self._lock:
            times = list(self._times)
        if len(times) < 2 or times[-1] <= times[0]:
            return None
        return (len(times) - 1) / (times[-1] - times[0])

    def close(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=self.link.timeout_s + self.link.connect_timeout_s + 1.0)

    def _loop(self) -> None:
        reader = self.link.reader()
        while not self._stop.is_set():
            if self.watchers == 0:
                self._wake.wait(1.0)
                self._wake.clear()
                continue
            t0 = time.monotonic()
            try:
                self._store(reader.call(call_of(CellCommands.view, ViewRequest(self.width_px))))
            except CommandError as exc:
                self.problem = f"no picture: {exc.code}: {exc.message}"
            except (ClientError, OSError, ValueError) as exc:
                self.problem = f"no picture: the service cannot be reached: {exc}"
            self._stop.wait(max(0.0, self.period_s - (time.monotonic() - t0)))
        reader.close()

    def _store(self, reply: ViewReply) -> None:
        self.picture = reply
        self.problem = None
        with self._lock:
            self.received += 1
            self._times.append(time.monotonic())
