"""The deploy files: example configuration, hardened unit, install script."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

from omnisort_hw.config.cell import CellConfig

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
UNIT = DEPLOY / "omnisort.service"
UI_UNIT = DEPLOY / "omnisort-ui.service"


def test_example_config_parses_and_documents_every_key() -> None:
    text = (DEPLOY / "cell.example.toml").read_text()
    settings = CellConfig.from_mapping(tomllib.loads(text))
    assert settings.service.host == "127.0.0.1"
    lines = text.splitlines()
    section = None
    for i, line in enumerate(lines):
        if line.startswith("["):
            section = line.strip("[]")
        elif section in {"service", "storage", "logging"} and re.match(r"^\w+\s*=", line):
            assert lines[i - 1].lstrip().startswith("#"), f"undocumented key: {line}"


def _unit_settings(unit: Path = UNIT) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for line in unit.read_text().splitlines():
        if "=" in line and not line.startswith("#"):
            key, _, value = line.partition("=")
            out.setdefault(key.strip(), []).append(value.strip())
    return out


def test_unit_is_hardened() -> None:
    u = _unit_settings()
    assert u["Type"] == ["notify"] and u["WatchdogSec"] and u["Restart"] == ["on-failure"]
    assert u["User"] == ["omnisort"] and u["SupplementaryGroups"] == ["video dialout"]
    assert u["ProtectSystem"] == ["strict"]
    assert u["ReadWritePaths"] == ["/var/lib/omnisort /var/log/omnisort"]
    assert u["NoNewPrivileges"] == ["true"] and u["CapabilityBoundingSet"] == [""]
    assert u["RestrictAddressFamilies"] == ["AF_UNIX AF_INET AF_INET6"]
    assert u["DevicePolicy"] == ["closed"]
    assert set(u["DeviceAllow"]) == {
        "char-video4linux rw",
        "char-ttyS rw",
        "char-ttyUSB rw",
        "char-ttyACM rw",
    }
    assert "@system-service" in u["SystemCallFilter"]
    for key in ("PrivateTmp", "ProtectHome", "ProtectKernelTunables", "ProtectControlGroups"):
        assert u[key] == ["true"], key


def test_ui_unit_is_hardened_and_cannot_read_the_token(tmp_path: Path) -> None:
    """The interface runs as a user of its own with a copy of the cell file alone, and what it
    reads of that file does not open the token file."""
    from omnisort_hw.config.ui import load_ui_settings

    u = _unit_settings(UI_UNIT)
    assert u["ExecStart"] == ["/opt/omnisort/venv/bin/omnisort ui --config %d/cell.toml"]
    assert u["LoadCredential"] == ["cell.toml:/etc/omnisort/cell.toml"]
    assert u["DynamicUser"] == ["true"] and "User" not in u and "SupplementaryGroups" not in u
    assert u["IPAddressDeny"] == ["any"] and u["IPAddressAllow"] == ["localhost"]
    assert u["ProtectSystem"] == ["strict"] and u["CapabilityBoundingSet"] == [""]
    for key in ("PrivateDevices", "PrivateTmp", "ProtectHome", "NoNewPrivileges"):
        assert u[key] == ["true"], key
    cell = tmp_path / "cell.toml"
    cell.write_text(
        '[service]\nport = 29100\ntoken_file = "/nonexistent/omnisort/token"\n'
        "[ui]\nport = 29180\nallow_operator = false\n"
    )
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.errors import ConfigError

    with pytest.raises(ConfigError, match="token_file"):
        load_cell_config(cell)  # what the service reads: the token
    settings = load_ui_settings(cell)  # what the interface reads: never the token
    assert (settings.service_host, settings.service_port) == ("127.0.0.1", 29100)
    assert (settings.ui.port, settings.ui.allow_operator) == (29180, False)


@pytest.mark.parametrize("unit", [UNIT, UI_UNIT], ids=lambda u: u.name)
@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze")
def test_systemd_analyze_security_exposure(unit: Path) -> None:
    proc = subprocess.run(
        ["systemd-analyze", "security", "--offline=true", "--no-pager", str(unit)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    m = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", proc.stdout + proc.stderr)
    if m is None:
        pytest.skip(f"systemd-analyze gave no score here: {proc.stderr[-300:]}")
    assert float(m.group(1)) <= 2.0


def test_install_script_is_valid_bash() -> None:
    script = DEPLOY / "install.sh"
    assert subprocess.run(["bash", "-n", str(script)], timeout=30).returncode == 0
    text = script.read_text()
    assert "set -euo pipefail" in text
    if shutil.which("shellcheck"):
        proc = subprocess.run(
            ["shellcheck", str(script)], capture_output=True, text=True, timeout=60
        )
        assert proc.returncode == 0, proc.stdout


def test_shipped_sim_cell_file_is_the_generated_one(tmp_path: Path) -> None:
    """`deploy/cell.sim.toml` is what the generator gives (regenerate it with `python -m
    sim_backend.virtual_cell.cell_file --sim`), loads, and is the demo's cell at its width."""
    pytest.importorskip("pybullet")
    from omnisort_hw.config.cell import load_cell_config
    from omnisort_hw.service.demo import write_config
    from sim_backend.scene import load_scene
    from sim_backend.virtual_cell.cell_file import sim_cell_file_text

    shipped = DEPLOY / "cell.sim.toml"
    assert shipped.read_text() == sim_cell_file_text()
    cell = load_cell_config(shipped)
    assert {cell.devices.camera.backend, cell.devices.laser.backend, cell.devices.arm.backend} == {
        "sim"
    }
    scene = load_scene("sorting")
    assert scene.target is not None
    assert (cell.target.kind, cell.target.separation_mm) == (
        "two-sided",
        scene.target.separation_mm,
    )
    assert cell.sorting is not None and cell.sorting.from_scene
    assert cell.registration is not None and cell.registration.board.square_mm == 40.0
    assert cell.storage.state_dir.resolve() == DEPLOY.parent / "build" / "sim-cell" / "state"
    assert cell.logging.log_dir.resolve() == DEPLOY.parent / "build" / "sim-cell" / "logs"
    demo = write_config(tmp_path, 320).read_text()
    assert demo == sim_cell_file_text(width=320, state_dir="state", log_dir="logs")


INSTALL = DEPLOY / "install.sh"


def _install(*args: str) -> subprocess.CompletedProcess[str]:
    """install.sh with `args` (the tests only use --dry-run and refusals: nothing installed)."""
    return subprocess.run(["bash", str(INSTALL), *args], capture_output=True, text=True, timeout=60)


def _stand_in_wheel(folder: Path, version: str = "0.1.0") -> Path:
    """A minimal, valid wheel named like the project's (pip resolves it; it holds no code)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"omnisort_hw-{version}-py3-none-any.whl"
    info = f"omnisort_hw-{version}.dist-info"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(
            f"{info}/METADATA", f"Metadata-Version: 2.1\nName: omnisort-hw\nVersion: {version}\n"
        )
        zf.writestr(
            f"{info}/WHEEL",
            "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
        )
        zf.writestr(f"{info}/RECORD", "")
    return path


def test_install_online_dry_run_builds_the_checkout() -> None:
    proc = _install("--dry-run")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[-1].endswith(f"--upgrade {DEPLOY.parent}")
    assert "--no-index" not in proc.stdout


def test_install_from_a_wheelhouse_uses_no_index(tmp_path: Path) -> None:
    _stand_in_wheel(tmp_path / "wheelhouse")
    for flag in ("--wheelhouse", "--offline"):
        proc = _install(flag, str(tmp_path / "wheelhouse"), "--dry-run")
        assert proc.returncode == 0, proc.stderr
        lines = proc.stdout.splitlines()
        assert len(lines) == 2 and all(
            f"--no-index --find-links {tmp_path / 'wheelhouse'}" in line for line in lines
        ), lines
        assert "--upgrade pip" not in proc.stdout
        assert lines[0].endswith("--upgrade omnisort-hw")


def test_install_refuses_a_wheelhouse_without_the_project(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    proc = _install("--wheelhouse", str(tmp_path / "empty"), "--dry-run")
    assert proc.returncode == 2 and "holds no omnisort_hw wheel" in proc.stderr
    proc = _install("--wheelhouse")
    assert proc.returncode == 2 and "needs a folder of wheels" in proc.stderr
    proc = _install("--bogus")
    assert proc.returncode == 2 and "unknown argument --bogus" in proc.stderr


def test_pip_resolves_the_project_from_the_wheelhouse_alone(tmp_path: Path) -> None:
    """What install.sh runs offline finds the project in the wheelhouse, never the index: a
    project wheel built here when the build backend is installed, else a stand-in."""
    house = tmp_path / "wheelhouse"
    build = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "--no-index",
            "--quiet",
            str(DEPLOY.parent),
            "-w",
            str(house),
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    built = build.returncode == 0
    if not built:
        _stand_in_wheel(house)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--dry-run",
            "--no-deps",
            "--no-index",
            "--find-links",
            str(house),
            "--ignore-installed",
            "omnisort-hw",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "Would install omnisort-hw-0.1.0" in proc.stdout, (built, proc.stdout)
