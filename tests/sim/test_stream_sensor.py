"""The virtual cell's camera stream in "real camera" mode exposes its frames with the sensor
model (`sim_backend.sensor`): a new noise draw per rendered state, the laser switched in the
light (not painted), and the clean picture underneath."""

from __future__ import annotations

import multiprocessing as mp
import threading

import numpy as np
import pytest

pytest.importorskip("pybullet", reason="the simulated cell needs pybullet")

from sim_backend.devices import SimCell
from sim_backend.virtual_cell.camera_stream import _render_worker, world_state

WIDTH = 480


def _frames(states: list[dict], degraded: bool, effects: bool = False) -> list[np.ndarray]:
    here, there = mp.Pipe()
    worker = threading.Thread(
        target=_render_worker,
        args=("sorting", WIDTH, WIDTH, 0, degraded, effects, there),
        daemon=True,
    )
    worker.start()
    try:
        assert here.poll(120.0), "the renderer did not start"
        here.recv()
        out = []
        for state in states:
            here.send(state)
            assert here.poll(120.0), "no frame within 120 s"
            out.append(here.recv()[1])
        return out
    finally:
        here.send(None)
        worker.join(30.0)


def test_degraded_stream_frames_come_from_the_sensor_model() -> None:
    cell = SimCell.from_scene("sorting", seed=0, width=WIDTH, height=WIDTH)
    try:
        on = world_state(cell)
        on["laser"] = True
        off = {**on, "laser": False}
    finally:
        cell.close()
    a, b, dark = _frames([on, on, off], degraded=True)
    (clean,) = _frames([on], degraded=False)
    assert a.shape == clean.shape == (WIDTH, WIDTH, 3)
    diff = a.astype(float) - b.astype(float)
    assert 0.5 < diff.std() < 20.0  # a fresh draw of shot and read noise, a few levels
    # the laser is light the sensor adds: on - off shows it far above what two draws of the
    # same state differ by (their red difference beyond 6 noise sigma: ~1e-9 of the pixels)
    sigma = diff[..., 2].std()
    laser = (a[..., 2].astype(float) - dark[..., 2]) > 6.0 * sigma
    noise = np.abs(diff[..., 2]) > 6.0 * sigma
    assert laser.sum() >= 20 and noise.sum() <= 2, (laser.sum(), noise.sum())


def test_with_the_effects_the_stream_is_the_colour_cameras() -> None:
    """`--effects`: each frame of the stream is the one the sensor with the colour camera's
    effects (crosstalk, chromatic aberration, bloom, Bayer: `scene.with_camera_effects`)
    exposes of that state, draw for draw; without them, another."""
    from sim_backend.exposed_frames import ExposedFrames
    from sim_backend.scene import load_scene, with_camera_effects
    from sim_backend.sensor import Exposure

    cell = SimCell.from_scene(
        with_camera_effects(load_scene("sorting")), seed=0, width=WIDTH, height=WIDTH
    )
    try:
        on = world_state(cell)
        on["laser"] = True
        cell.world.laser_on = True
        sensor = ExposedFrames(cell.world, cell.model, 0, cell.lighting)
        assert sensor.params.effects is not None and sensor.params.effects.bayer
        settings = Exposure(
            laser_on=True, flicker_depth=cell.lighting.flicker_depth, pixel_format="BGR3"
        )
        expected, _ = sensor.frame(settings, 1)  # the worker's first draw
    finally:
        cell.close()
    (streamed,) = _frames([on], degraded=True, effects=True)
    (plain,) = _frames([on], degraded=True, effects=False)
    assert np.array_equal(streamed, expected)
    assert np.abs(plain.astype(int) - expected.astype(int)).mean() > 1.0
