"""The operator interface's test peers: the simulated cell's service (`omnisort serve`, as
systemd runs it), `omnisort ui` as its own process, and Debian's Chromium driven headless
through its chromedriver."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from omnisort_hw.service.demo import calibrate_from_truth, write_config
from tests.service.sim_cell import pace_the_arm

TOKEN = "ui-test-token-7f3a"
PROJECT_ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"


def sim_cell_file(
    tmp: Path, width: int = 320, realtime: bool = True, view_period_s: float = 0.5
) -> Path:
    """The simulated cell's file with its true calibration, a service token, and (`realtime`)
    an arm paced to the wall clock, so a sort lasts long enough to watch and stop."""
    config = write_config(tmp, width)
    calibrate_from_truth(config)
    if realtime:
        pace_the_arm(config)
    config.write_text(
        config.read_text() + f'\n[service]\ntoken = "{TOKEN}"\n\n[ui]\nstatus_period_s = 0.25\n'
        f"view_period_s = {view_period_s}\n"
    )
    return config


def knock_calibration(config: Path, angle_deg: float, axis: tuple[float, float, float]) -> None:
    """A drifted system on the simulated cell: the stored camera rotation turned by `angle_deg`
    about `axis` of S (as a knock turns the camera away from what was calibrated), saved
    through the calibration store (valid checksum, the previous version kept)."""
    import json

    import numpy as np
    from scipy.spatial.transform import Rotation

    from omnisort_hw.pipeline.calibration_store import CalibrationStore

    state = config.parent / "state"
    record = json.loads((state / "system.json").read_text())
    payload = {k: v for k, v in record.items() if k not in ("storage", "checksum")}
    turn = Rotation.from_rotvec(np.radians(angle_deg) * np.asarray(axis, float)).as_matrix()
    R = np.asarray(payload["camera_rotation"]["matrix"], float)
    payload["camera_rotation"]["matrix"] = (turn @ R).tolist()
    store = CalibrationStore(state_dir=state, max_age_days=None, expected_serial=None)
    store.save("system", payload, camera_serial=record["storage"]["camera_serial"])


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_ui(
    config: Path, service_port: int, workdir: Path, timeout_s: float = 60.0
) -> tuple[subprocess.Popen[bytes], str]:
    """`omnisort ui` on a free loopback port; returns once its page answers."""
    port = free_port()
    # Not PYTEST_CURRENT_TEST: NiceGUI would take the child for its own screen test.
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["PYTHONPATH"] = str(PROJECT_ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    log = open(workdir / "ui.log", "wb")  # noqa: SIM115 - the child writes it until it ends
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "omnisort_hw.cli",
            "ui",
            "--config",
            str(config),
            "--port",
            str(port),
            "--service-port",
            str(service_port),
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
        cwd=workdir,
    )
    url = f"http://127.0.0.1:{port}/"
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"omnisort ui exited: {(workdir / 'ui.log').read_text()[-3000:]}")
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                if r.status == 200:
                    return proc, url
        except OSError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError(f"omnisort ui did not answer in {timeout_s} s")


def stop_process(proc: subprocess.Popen[bytes], timeout_s: float = 20.0) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)


def chromium(width: int = 1400, height: int = 1000):  # -> selenium WebDriver
    """Headless Debian Chromium through its chromedriver, offline, in a fresh profile."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not Path(p).exists()]
    if missing:
        raise RuntimeError(
            f"{', '.join(missing)} missing: install Debian's chromium and chromium-driver "
            "(`make browser`; .ci/run does it)"
        )
    profile = tempfile.mkdtemp(prefix="omnisort-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={profile}",
        f"--window-size={width},{height}",
    ):
        opts.add_argument(arg)
    driver = webdriver.Chrome(options=opts, service=Service(CHROMEDRIVER))
    driver.set_page_load_timeout(60)  # a hang guard (see browser_page.UI_S)
    driver.set_script_timeout(60)
    driver._omnisort_profile = profile  # type: ignore[attr-defined]
    return driver


def quit_chromium(driver) -> None:
    try:
        driver.quit()
    finally:
        shutil.rmtree(getattr(driver, "_omnisort_profile", ""), ignore_errors=True)
