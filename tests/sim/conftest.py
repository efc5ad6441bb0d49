"""Shared renders for the simulator tests (session-scoped: each scene is rendered once)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest

from sim_backend.scene import load_scene, sized
from sim_backend.scene_images import render_scene

TEST_WIDTH = 960


@pytest.fixture(scope="session", autouse=True)
def _one_thread_opencv() -> None:
    """Keep OpenCV to one thread: the machine is shared and renders must not depend on it."""
    cv2.setNumThreads(1)


def _render(name: str, width: int = TEST_WIDTH, **kw: Any) -> tuple[np.ndarray, dict[str, Any]]:
    image, truth = render_scene(sized(load_scene(name), width), **kw)
    assert truth is not None
    return image, truth


@pytest.fixture(scope="session")
def checkerboards_render() -> tuple[np.ndarray, dict[str, Any]]:
    """The two vertical checkerboards with the laser on, 960 x 960."""
    return _render("checkerboards", seed=1)


@pytest.fixture(scope="session")
def two_sided_render() -> tuple[np.ndarray, dict[str, Any]]:
    """The two-sided target with the laser on, 960 x 960."""
    return _render("two_sided", seed=1)
