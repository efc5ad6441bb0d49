"""The deploy files: example configuration, hardened unit, install script."""

from __future__ import annotations

import re
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest

from omnisort_hw.config.cell import CellConfig

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
UNIT = DEPLOY / "omnisort.service"


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


def _unit_settings() -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
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


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze")
def test_systemd_analyze_security_exposure() -> None:
    proc = subprocess.run(
        ["systemd-analyze", "security", "--offline=true", "--no-pager", str(UNIT)],
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
