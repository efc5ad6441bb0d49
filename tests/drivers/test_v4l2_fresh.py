"""The fresh-frame policy of the V4L2 path, on a scripted capture (no camera can run here).

`FakeV4L2Capture` behaves like OpenCV's V4L2 capture with a camera streaming at `fps`: frames
are produced continuously and queued in the driver's buffers (when they are full, either the
oldest frame is overwritten or, as V4L2 does, the new one is dropped); `grab()` dequeues the
oldest at once when one is waiting and blocks until the next one otherwise;
`get(CAP_PROP_POS_MSEC)` is the dequeued frame's kernel timestamp on CLOCK_MONOTONIC (or 0
when `monotonic_stamps` is False, as some drivers report). The V4L2Camera must return a frame
exposed after grab() began.
"""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from drivers.errors import DeviceTimeoutError
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig

pytestmark = pytest.mark.timeout(10)

FPS = 50.0


class FakeV4L2Capture:
    def __init__(
        self,
        buffers: int = 4,
        monotonic_stamps: bool = True,
        keeps: str = "newest",
        dequeue_s: float = 0.0,
    ) -> None:
        self.period = 1.0 / FPS
        self.buffers = buffers
        self.monotonic_stamps = monotonic_stamps
        self.keeps = keeps  # "newest": old frames overwritten; "oldest": new ones dropped (V4L2)
        self.dequeue_s = dequeue_s  # every dequeue takes this long, as when the reader is preempted
        self.start = time.monotonic()
        self.next_index = 0  # index of the next frame the camera produces into the queue
        self.queue: list[int] = []  # indexes of the frames waiting in kernel buffers
        self.stamp = 0.0
        self.stamps: list[float] = []  # every dequeued frame's capture time, in order
        self.exposure = -1.0

    def _produced(self, now: float) -> int:
        return int((now - self.start) / self.period)

    def _fill(self, now: float) -> None:
        for index in range(self.next_index, self._produced(now)):
            if len(self.queue) < self.buffers:
                self.queue.append(index)
            elif self.keeps == "newest":
                self.queue = [*self.queue[1:], index]
        self.next_index = max(self.next_index, self._produced(now))

    def grab(self) -> bool:
        self._fill(time.monotonic())
        if not self.queue:
            next_frame = self.start + (self.next_index + 1) * self.period
            time.sleep(max(0.0, next_frame - time.monotonic()))
            self._fill(time.monotonic())
        index = self.queue.pop(0)
        time.sleep(self.dequeue_s)
        self.stamp = self.start + (index + 1) * self.period
        self.stamps.append(self.stamp)
        return True

    def retrieve(self) -> tuple[bool, np.ndarray]:
        return True, np.zeros((4, 4, 3), np.uint8)

    def get(self, prop: int) -> float:
        if prop == cv2.CAP_PROP_POS_MSEC:
            return self.stamp * 1000.0 if self.monotonic_stamps else 0.0
        if prop == cv2.CAP_PROP_BUFFERSIZE:
            return float(self.buffers)  # what OpenCV reports after the driver allocated them
        if prop == cv2.CAP_PROP_EXPOSURE:
            return self.exposure
        return 0.0

    def set(self, prop: int, value: float) -> bool:
        if prop == cv2.CAP_PROP_EXPOSURE:
            self.exposure = value
        return True

    def release(self) -> None:
        pass


def camera_on(fake: FakeV4L2Capture, **settings: object) -> V4L2Camera:
    cfg = V4L2CameraConfig(device="/dev/video0", api="v4l2", fps=FPS, **settings)  # type: ignore[arg-type]
    cam = V4L2Camera(cfg)
    cam._cap = fake  # as if connect() had opened the device
    return cam


@pytest.mark.parametrize("keeps", ["newest", "oldest"])
@pytest.mark.parametrize("monotonic_stamps", [True, False])
def test_stale_buffered_frames_are_skipped(monotonic_stamps: bool, keeps: str) -> None:
    fake = FakeV4L2Capture(buffers=4, monotonic_stamps=monotonic_stamps, keeps=keeps)
    cam = camera_on(fake, settle_frames=0)
    time.sleep(0.2)  # the buffers fill with frames older than the next grab() call
    t_call = time.monotonic()
    frame = cam.grab(timeout_s=1.0)
    assert frame.timestamp >= t_call
    assert fake.stamp >= t_call, "the frame returned was captured before grab() was called"


def test_without_stamps_a_slow_stale_dequeue_is_not_taken_for_a_fresh_frame() -> None:
    # Every dequeue takes a whole frame period, as on a loaded machine: only counting the
    # buffers can tell the queued frames from the first one taken after the call.
    fake = FakeV4L2Capture(buffers=4, monotonic_stamps=False, keeps="oldest", dequeue_s=1 / FPS)
    cam = camera_on(fake, settle_frames=0)
    time.sleep(0.2)
    t_call = time.monotonic()
    cam.grab(timeout_s=1.0)
    assert fake.stamp >= t_call, "a frame queued before grab() was returned"
    assert len([s for s in fake.stamps if s >= t_call]) == 1  # and the first fresh one at that


def test_without_stamps_each_exposure_period_costs_one_more_frame() -> None:
    fake = FakeV4L2Capture(buffers=2, monotonic_stamps=False, keeps="oldest")
    cam = camera_on(fake, settle_frames=0)
    cam.set_exposure_ms(30.0)  # 1.5 frame periods: two frames may have begun exposing earlier
    cam._discard = 0
    time.sleep(0.1)
    before = len(fake.stamps)
    cam.grab(timeout_s=1.0)
    assert len(fake.stamps) - before == 2 + 2 + 1


def test_exposure_time_counts_into_freshness() -> None:
    fake = FakeV4L2Capture()
    cam = camera_on(fake, settle_frames=0)
    cam.set_exposure_ms(30.0)  # 1.5 frame periods
    assert fake.exposure == pytest.approx(300.0)  # V4L2 exposure_absolute counts 100 us
    time.sleep(0.1)
    t_call = time.monotonic()
    frame = cam.grab(timeout_s=1.0)
    assert frame.timestamp >= t_call + 0.030


def test_settle_frames_are_discarded_after_an_exposure_change() -> None:
    # Counted in frames, not timed: the machine's load cannot pass or fail it.
    fake = FakeV4L2Capture()
    cam = camera_on(fake, settle_frames=3)
    cam._discard = 0
    t_call = time.monotonic()
    cam.grab(timeout_s=1.0)
    assert len([s for s in fake.stamps if s >= t_call]) == 1  # no change: the first fresh one
    cam.set_exposure_ms(1.0)
    t_call = time.monotonic()
    cam.grab(timeout_s=1.0)
    fresh = [s for s in fake.stamps if s >= t_call]
    assert len(fresh) == 4  # three frames exposed after the change discarded, the fourth kept
    assert fake.stamp == fresh[-1]


def test_a_source_that_only_gives_stale_frames_times_out() -> None:
    fake = FakeV4L2Capture()
    # A driver that keeps handing out a frame stamped one second ago.
    fake.get = lambda prop: (time.monotonic() - 1.0) * 1000.0  # type: ignore[method-assign]
    cam = camera_on(fake, settle_frames=0)
    with pytest.raises(DeviceTimeoutError, match="stale"):
        cam.grab(timeout_s=1.0)
