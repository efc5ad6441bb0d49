"""Measurement captures: the stripe from laser-on/laser-off pairs, averaged, exposed for the
task, uncompressed where the camera offers it, re-exposed when the stripe core clips.

One use case for the service (calibrate extrinsics, map, locate without an image) and the CLI
driving a configured cell. What it does, in order:

1. Pixel format: the first of `UNCOMPRESSED_FORMATS` the camera offers (MJPG's 4:2:0 chroma
   and block artefacts move stripe centres); a camera that cannot tell keeps its format and the
   record says so.
2. Stripe frames at the stripe exposure and gain (short: the laser is bright, the scene is not):
   N laser-on and N laser-off frames, interleaved (on, off, on, off: slow light changes fall on
   both). Every switch is read back from the device; a read-back that differs raises
   `LaserSwitchError` naming the laser. The laser's light is on - off in linear light
   (`core.laser_difference`); no laser light in it raises `NoLaserDifferenceError` naming the
   laser and the camera. When more than `clipped_limit` of the stripe's pixels clipped, the
   exposure is halved and the stripe frames taken again, at most `max_retries` times, then
   `CaptureSaturatedError`.
3. Board frames (laser off) at the board exposure and gain, averaged, for the target's edges,
   markers and colours.
4. Exposure, gain, format and the laser are put back as they were, whatever happened.

The record says what was used (frames, exposures tried, format, flicker gain, clipped share)
and the capture time: the sum of exposures and the time spent switching the laser, and the
wall time. Every frame goes to the run log. Nothing is returned from a bad capture.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivers.base import UNCOMPRESSED_FORMATS, Camera, LaserSwitch
from drivers.errors import DeviceError, UnsupportedError
from omnisort_hw.config.capture import CaptureSettings
from omnisort_hw.core.laser_difference import (
    FrameStack,
    LaserDifference,
    corrected_tone,
    encode_mean,
    laser_difference,
    response_gamma,
    stack_frames,
)
from omnisort_hw.core.laser_stripe import laser_stripe_points
from omnisort_hw.core.radiometry import ToneCurve
from omnisort_hw.runlog import NullLog, RunLog

RESPONSE_RATIO = 2.0  # the board's second exposure, for the camera's response (both whole
# mains periods when the first is)


def _relinearise(stack: FrameStack, gamma: float) -> FrameStack:
    """A stack linearised with the nominal curve, taken to light with the measured one."""
    if abs(gamma - 1.0) < 1e-6:
        return stack
    return FrameStack(stack.mean ** np.float32(1.0 / gamma), stack.clipped, stack.frames)


# Pixels of laser light a real difference has at least: noise alone passes the 6-sigma test
# in ~1e-9 of the pixels (a few in a 4 Mpx image), a stripe in thousands.
MIN_STRIPE_PIXELS = 30
# ... or, for a faint stripe (small image, dark surface), points the extractor chains into a
# stripe (its chains need 4 points, texture-free noise gives none)
MIN_STRIPE_POINTS = 8


class LaserSwitchError(DeviceError):
    """The laser's read-back state differs from what was commanded."""

    code = "laser_not_switching"


class NoLaserDifferenceError(DeviceError):
    """Laser-on and laser-off frames show no laser light: the laser did not light the scene."""

    code = "no_laser_difference"


class CaptureSaturatedError(DeviceError):
    """The stripe core stayed clipped at the shortest exposure tried."""

    code = "capture_saturated"


@dataclass
class MeasurementCapture:
    """What one capture gives: the laser-light image and its stripe points, the laser-off
    board image (None when not asked for), and the record of how it was taken."""

    stripe_image: np.ndarray
    stripe_px: np.ndarray
    board_image: np.ndarray | None
    record: dict[str, Any] = field(default_factory=dict)
    tone: ToneCurve | None = None  # the camera's curve as measured (None: not measured)
    scene_image: np.ndarray | None = None  # a laser-off frame of the stripe's: the pictures'


class _Timer:
    """Exposure time summed over frames and time spent switching the laser."""

    def __init__(self) -> None:
        self.exposure_ms = 0.0
        self.switching_s = 0.0
        self.frames = 0


def _try(fn: Any, *args: Any) -> Any:
    try:
        return fn(*args)
    except UnsupportedError:
        return None


def _switch(laser: LaserSwitch, on: bool, timer: _Timer) -> None:
    t0 = time.monotonic()
    laser.set(on)
    state = laser.state()
    timer.switching_s += time.monotonic() - t0
    if bool(state) != on:
        raise LaserSwitchError(
            f"{laser.name}: commanded {'on' if on else 'off'} but it reads back "
            f"{'on' if state else 'off'}; check the laser's wiring and interlock",
            device=laser.name,
        )


def _grab(camera: Camera, timer: _Timer, exposure_ms: float) -> np.ndarray:
    frame = camera.grab()
    timer.exposure_ms += exposure_ms
    timer.frames += 1
    return np.asarray(frame.image)


def _expose(camera: Camera, exposure_ms: float, gain: float) -> tuple[float, bool]:
    """Set exposure and gain where the camera can: (exposure in effect in ms, whether the
    camera took it; a file or stream keeps what it was recorded with)."""
    try:
        camera.set_exposure_ms(exposure_ms)
        took = True
    except UnsupportedError:
        took = False
    _try(camera.set_gain, gain)
    got = _try(camera.get_exposure_ms) if took else None
    return (float(got) if got else exposure_ms), took


def _pick_format(camera: Camera, prefer_uncompressed: bool) -> str:
    offered = camera.pixel_formats
    if prefer_uncompressed:
        for fourcc in UNCOMPRESSED_FORMATS:
            if fourcc in offered:
                if fourcc != camera.pixel_format:
                    camera.set_pixel_format(fourcc)
                return fourcc
    return camera.pixel_format or "as delivered (the source cannot tell or switch)"


def single_frame(
    camera: Camera, laser: LaserSwitch, log: RunLog = NullLog, color: str = "red"
) -> MeasurementCapture:
    """One laser-on frame as it comes, the stripe found in it (the single-frame method);
    `color`: the laser's."""
    timer = _Timer()
    t0 = time.monotonic()
    _switch(laser, True, timer)
    exposure = _try(camera.get_exposure_ms) or 0.0
    image = _grab(camera, timer, exposure)
    log.image("capture/single/on", image)
    pixels = laser_stripe_points(image, color=color)
    record = {
        "method": "single frame",
        "frames": 1,
        "pixel_format": camera.pixel_format or "as delivered",
        "exposure_ms": exposure,
        "capture_s": round(timer.exposure_ms / 1000.0 + timer.switching_s, 4),
        "wall_s": round(time.monotonic() - t0, 4),
    }
    return MeasurementCapture(image, pixels, image, record)


def capture_measurement(
    camera: Camera,
    laser: LaserSwitch,
    settings: CaptureSettings | None = None,
    log: RunLog = NullLog,
    board: bool = True,
    color: str = "red",
) -> MeasurementCapture:
    """A measurement capture (see the module docstring) of a `color` laser; raises the typed
    errors above."""
    cfg = settings or CaptureSettings()
    if not cfg.differencing:
        return single_frame(camera, laser, log, color)
    tone = ToneCurve.parse(camera.tone_curve)
    t_start = time.monotonic()
    timer = _Timer()
    old_exposure = _try(camera.get_exposure_ms)
    old_gain = _try(camera.get_gain)
    old_format = camera.pixel_format
    old_laser = laser.state()
    tried: list[dict[str, Any]] = []
    try:
        fourcc = _pick_format(camera, cfg.prefer_uncompressed)
        board_image, gamma = None, 1.0
        if board:
            _switch(laser, False, timer)
            stacks = []
            for k, scale in enumerate((1.0, RESPONSE_RATIO)):
                used_b, took = _expose(camera, cfg.board_exposure_ms * scale, cfg.board_gain)
                frames = []
                for i in range(cfg.frames):
                    frames.append(_grab(camera, timer, used_b))
                    log.set_step("capture_frame", i)
                    log.image(f"capture/board/off_{k}", frames[-1])
                stacks.append((stack_frames(frames, tone, "board"), used_b))
                if not took:
                    break  # no exposure control: no second exposure, the nominal curve
            if len(stacks) == 2:
                (short, t_s), (long, t_l) = stacks
                gamma = response_gamma(short, long, t_l / t_s, tone)
                tone = corrected_tone(tone, gamma)
            frames_b = stacks[0][0]
            board_image = encode_mean(_relinearise(frames_b, gamma), tone)
            log.image("capture/board/mean", board_image)
        exposure = cfg.stripe_exposure_ms
        diff: LaserDifference | None = None
        for attempt in range(cfg.max_retries + 1):
            used, _ = _expose(camera, exposure, cfg.stripe_gain)
            on: list[np.ndarray] = []
            off: list[np.ndarray] = []
            for i in range(cfg.frames):
                _switch(laser, True, timer)
                on.append(_grab(camera, timer, used))
                _switch(laser, False, timer)
                off.append(_grab(camera, timer, used))
                log.set_step("capture_frame", attempt * cfg.frames + i)
                log.image("capture/stripe/on", on[-1])
                log.image("capture/stripe/off", off[-1])
            diff = laser_difference(
                stack_frames(on, tone, "laser-on"), stack_frames(off, tone, "laser-off"), color
            )
            tried.append(
                {
                    "exposure_ms": round(used, 4),
                    "gain": cfg.stripe_gain,
                    "clipped_fraction": round(diff.clipped_fraction, 4),
                    "stripe_pixels": diff.stripe_pixels,
                }
            )
            faint = diff.stripe_pixels < MIN_STRIPE_PIXELS
            found = laser_stripe_points(diff.image, light_only=True, color=color)
            if faint and len(found) < MIN_STRIPE_POINTS:
                raise NoLaserDifferenceError(
                    f"{laser.name} reads back on, but {camera.name} sees no laser light between "
                    f"laser-on and laser-off frames ({diff.stripe_pixels} px above the noise): is "
                    "the laser powered, its aperture covered, or the camera looking elsewhere?",
                    device=laser.name,
                )
            if diff.clipped_fraction <= cfg.clipped_limit:
                break
            exposure = used / 2.0
        else:
            raise CaptureSaturatedError(
                f"{camera.name}: the laser stripe's core stays clipped "
                f"({100 * tried[-1]['clipped_fraction']:.1f} % of its pixels) after "
                f"{cfg.max_retries} shorter exposures down to {tried[-1]['exposure_ms']} ms; "
                "lower [capture].stripe_gain or the laser power",
                device=camera.name,
            )
        assert diff is not None
        log.image("capture/stripe/difference", diff.image)
        pixels = laser_stripe_points(diff.image, light_only=True, color=color)
        log.points2d("capture/stripe/difference/laser", pixels, color=(255, 0, 0), radius=1)
    finally:
        _restore(camera, laser, old_exposure, old_gain, old_format, old_laser)
    record = {
        "method": "laser on/off difference",
        "frames": cfg.frames,
        "pixel_format": fourcc,
        "stripe_exposures": tried,
        "retries": len(tried) - 1,
        "flicker_gain": round(diff.flicker_gain, 4),
        "response_gamma": round(gamma, 4),
        "tone_curve": tone.name,
        "board_exposure_ms": cfg.board_exposure_ms if board else None,
        "frames_grabbed": timer.frames,
        "exposure_s": round(timer.exposure_ms / 1000.0, 4),
        "laser_switching_s": round(timer.switching_s, 4),
        "capture_s": round(timer.exposure_ms / 1000.0 + timer.switching_s, 4),
        "wall_s": round(time.monotonic() - t_start, 4),
        "stripe_points": int(pixels.shape[0]),
    }
    log.text("capture/record", str(record))
    return MeasurementCapture(diff.image, pixels, board_image, record, tone, off[-1])


def _restore(
    camera: Camera,
    laser: LaserSwitch,
    exposure: float | None,
    gain: float | None,
    fourcc: str,
    laser_on: bool,
) -> None:
    """Put the camera and the laser back; errors here must not hide the capture's own."""
    steps: list[tuple[Any, Any]] = [(laser.set, laser_on)]
    if exposure is not None:
        steps.append((camera.set_exposure_ms, exposure))
    if gain is not None:
        steps.append((camera.set_gain, gain))
    if fourcc and fourcc != camera.pixel_format:
        steps.append((camera.set_pixel_format, fourcc))
    for fn, arg in steps:
        with contextlib.suppress(DeviceError):
            fn(arg)
