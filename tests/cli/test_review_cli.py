"""`omnisort review`: headless refusal before anything starts, --png pictures, --web on loopback."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.cli.review_cmd import NO_DISPLAY, display_problem
from omnisort_hw.runlog import RunLog

PORTS = ("--web-port", "0", "--grpc-port", "0")  # any free ones: other runs may hold rerun's


def _headless_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return {**env, **extra}


def _review(*args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "review", *args],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )


@pytest.fixture(scope="module")
def rrd(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small run log: an image with a red point set and a line strip under it."""
    path = tmp_path_factory.mktemp("review") / "run.rrd"
    image = np.full((120, 160, 3), 40, np.uint8)
    image[:, 80:] = (200, 100, 0)  # BGR: the right half blue-ish
    with RunLog(path) as log:
        log.image("cam/image", image)
        log.points2d("cam/image/laser", np.array([[20.0, 30.0], [40.0, 60.0]]), color=(255, 0, 0))
        log.lines2d("cam/image/line", [np.array([[0.0, 100.0], [159.0, 100.0]])], color=(0, 255, 0))
    return path


def test_display_problem_follows_the_environment() -> None:
    assert display_problem({}, "linux") == NO_DISPLAY
    assert display_problem({"DISPLAY": ":0"}, "linux") is None
    assert display_problem({"WAYLAND_DISPLAY": "wayland-0"}, "linux") is None
    assert display_problem({}, "darwin") is None and display_problem({}, "win32") is None


def test_headless_review_refuses_before_starting_any_viewer(rrd: Path, tmp_path: Path) -> None:
    """No display: a typed error naming --web and --png, and the viewer is never spawned (a
    stand-in viewer would leave a mark), so nothing listens on rerun's port either."""
    mark = tmp_path / "viewer-was-started"
    stub = tmp_path / "viewer.sh"
    stub.write_text(f"#!/bin/sh\ntouch {mark}\n")
    stub.chmod(0o755)
    proc = _review(str(rrd), env=_headless_env(OMNISORT_RERUN=str(stub)))
    assert proc.returncode != 0
    assert "[no_display]" in proc.stderr and NO_DISPLAY in proc.stderr, proc.stderr
    assert "--web" in proc.stderr and "--png DIR" in proc.stderr
    assert not mark.exists()
    live = _review("--live", "127.0.0.1:9", env=_headless_env(OMNISORT_RERUN=str(stub)))
    assert live.returncode != 0 and NO_DISPLAY in live.stderr and not mark.exists()


def test_review_png_writes_the_images_with_their_points(rrd: Path, tmp_path: Path) -> None:
    out = tmp_path / "pics"
    proc = _review(str(rrd), "--png", str(out), env=_headless_env())
    assert proc.returncode == 0, proc.stderr
    png = out / "cam_image.png"
    assert str(png) in proc.stdout
    pic = cv2.imread(str(png))
    assert pic is not None and pic.shape == (120, 160, 3)
    assert tuple(pic[10, 120]) == (200, 100, 0)  # the image's own pixels, colours kept
    assert tuple(pic[30, 20]) == (0, 0, 255)  # the logged red point (RGB) drawn in BGR
    assert tuple(pic[100, 10]) != (40, 40, 40)  # the line strip drawn


@pytest.mark.slow
def test_review_web_serves_on_loopback_only(rrd: Path) -> None:
    """--web: rerun's web viewer answers over HTTP on 127.0.0.1, and every socket the viewer
    listens on is bound to a loopback address."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "omnisort_hw.cli", "review", str(rrd), "--web", *PORTS],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=_headless_env(),
        start_new_session=True,
    )
    try:
        url = None
        lines: list[str] = []
        deadline = time.monotonic() + 60
        assert proc.stdout is not None
        os.set_blocking(proc.stdout.fileno(), False)
        while url is None and time.monotonic() < deadline and proc.poll() is None:
            line = proc.stdout.readline()
            if not line:
                time.sleep(0.1)
                continue
            lines.append(line)
            found = re.search(r"Hosting a web-viewer at (http://[0-9.]+:\d+)", line)
            url = found.group(1) if found else None
        assert url is not None, "".join(lines)
        assert url.startswith("http://127."), url
        with urllib.request.urlopen(url, timeout=10) as resp:
            assert resp.status == 200 and b"<html" in resp.read(4096).lower()
        if shutil.which("ss"):
            ss = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, timeout=10)
            ours = [
                ln for ln in ss.stdout.splitlines() if "rerun" in ln and url.split(":")[-1] in ln
            ]
            assert ours, ss.stdout
            pids = set(re.findall(r"pid=(\d+)", ours[0]))
            mine = [ln for ln in ss.stdout.splitlines() if set(re.findall(r"pid=(\d+)", ln)) & pids]
            assert all(ln.split()[3].startswith("127.") for ln in mine), mine
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=15)
