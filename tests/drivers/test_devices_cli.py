"""`omnisort devices list|check` and `omnisort laser` against real peers on this machine."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.cli import main
from tests.drivers.modbus_peer import ModbusTestServer
from tests.drivers.serial_emulator import SerialDeviceEmulator

pytestmark = pytest.mark.timeout(30)


@pytest.fixture
def emulator() -> Iterator[SerialDeviceEmulator]:
    emu = SerialDeviceEmulator()
    yield emu
    emu.close()


def write_config(tmp_path: Path, laser: str, arm: str = "") -> Path:
    rec = tmp_path / "rec"
    rec.mkdir()
    for i in range(3):
        cv2.imwrite(str(rec / f"img_{i:03d}.png"), np.full((24, 32, 3), 40 * i, np.uint8))
    cfg = tmp_path / "cell.toml"
    cfg.write_text(
        '[camera]\nbackend = "v4l2"\napi = "images"\ndevice = "rec/img_%03d.png"\n\n'
        f"[laser]\n{laser}\n\n{arm}\n[service]\nport = 29999\n"
    )
    return cfg


def serial_laser(emu: SerialDeviceEmulator) -> str:
    return f'backend = "serial"\nport = "{emu.path}"\ntimeout_s = 0.2\nretries = 0'


def test_check_all_good_exits_zero_and_prints_a_table(tmp_path, emulator, capsys) -> None:
    cfg = write_config(tmp_path, serial_laser(emulator))
    assert main(["devices", "check", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split()[:5] == ["DEVICE", "BACKEND", "WHERE", "STATUS", "TIME"]
    rows = {line.split()[0]: line for line in out[1:]}
    assert " ok " in rows["camera"] and "frame 32x24" in rows["camera"]
    assert " ok " in rows["laser"] and "laser is OFF" in rows["laser"]
    assert "not configured" in rows["arm"]


def test_check_exits_one_and_names_the_failing_device(tmp_path, emulator, capsys) -> None:
    arm = '[arm]\nbackend = "ur_rtde"\nhost = "127.0.0.1"\nconnect_timeout_s = 1.0\n'
    cfg = write_config(tmp_path, serial_laser(emulator), arm)
    emulator.mode = "silent"
    assert main(["devices", "check", "--config", str(cfg), "--json"]) == 1
    rows = {r["device"]: r for r in json.loads(capsys.readouterr().out)["result"]["devices"]}
    assert rows["camera"]["ok"] is True
    assert rows["laser"]["status"] == "device_timeout"
    assert emulator.path in rows["laser"]["detail"]
    assert rows["arm"]["status"] == "device_not_found"
    assert "127.0.0.1:30004" in rows["arm"]["detail"]
    assert all(r["seconds"] < 3.0 for r in rows.values())


def test_check_modbus_laser(tmp_path, capsys) -> None:
    with ModbusTestServer() as server:
        laser = f'backend = "modbus"\ntcp_port = {server.port}\ncoil = 2\ntimeout_s = 0.3'
        cfg = write_config(tmp_path, laser)
        assert main(["devices", "check", "--config", str(cfg), "--only", "laser"]) == 0
    out = capsys.readouterr().out
    assert f"127.0.0.1:{server.port}" in out and "laser is OFF" in out
    assert "camera" not in out


def test_laser_on_off_state(tmp_path, emulator, capsys) -> None:
    cfg = write_config(tmp_path, serial_laser(emulator))
    assert main(["laser", "on", "--config", str(cfg)]) == 0
    assert emulator.laser_on is True
    assert "laser ON" in capsys.readouterr().out
    assert main(["laser", "state", "--config", str(cfg)]) == 0
    assert "laser ON" in capsys.readouterr().out
    assert main(["laser", "off", "--config", str(cfg)]) == 0
    assert emulator.laser_on is False


def test_laser_failure_is_a_coded_error_and_exit_two(tmp_path, capsys) -> None:
    cfg = write_config(tmp_path, 'backend = "serial"\nport = "/dev/ttyNOPE9"')
    assert main(["laser", "on", "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert "[device_not_found]" in err and "/dev/ttyNOPE9" in err


def test_bad_config_names_the_key(tmp_path, emulator, capsys) -> None:
    cfg = write_config(tmp_path, serial_laser(emulator) + "\nbaudrate = -5")
    assert main(["devices", "check", "--config", str(cfg)]) == 78
    assert "[laser].baudrate" in capsys.readouterr().err


def test_devices_list_runs(capsys) -> None:
    assert main(["devices", "list"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Cameras:") and "Serial ports:" in out
    assert main(["devices", "list", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["ok"] is True and set(doc["result"]) == {"cameras", "serial_ports"}
