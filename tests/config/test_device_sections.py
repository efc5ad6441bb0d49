"""Device sections of the cell TOML, the device factory and the example configuration."""

from __future__ import annotations

import dataclasses
import json
import re
import sys
import tomllib
import types
from pathlib import Path

import pytest

from drivers.modbus_laser import ModbusLaser, ModbusLaserConfig
from drivers.serial_laser import SerialLaser, SerialLaserConfig
from drivers.ur_arm import URArm, URArmConfig
from drivers.v4l2_camera import V4L2Camera, V4L2CameraConfig
from omnisort_hw.cell.devices import open_devices, open_laser
from omnisort_hw.config.cell import load_cell_config
from omnisort_hw.config.devices import parse_device_config
from omnisort_hw.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "cell.example.toml"


def parse(text: str, base: Path | None = None):
    return parse_device_config(tomllib.loads(text), base)


def error_key(text: str) -> str:
    with pytest.raises(ConfigError) as info:
        parse(text)
    key = info.value.key  # type: ignore[attr-defined]
    assert str(info.value).startswith(key)
    return key


def test_example_configuration_has_typed_device_sections() -> None:
    cell = load_cell_config(EXAMPLE).devices
    assert isinstance(cell.camera.settings, V4L2CameraConfig)
    assert isinstance(cell.laser.settings, SerialLaserConfig)
    assert cell.laser.settings.line_ending == "\r\n"
    assert isinstance(cell.arm.settings, URArmConfig)
    assert cell.arm.settings.workspace_min_mm == (-800.0, -800.0, -50.0)


def test_example_configuration_documents_every_device_key() -> None:
    lines = EXAMPLE.read_text().splitlines()
    section = None
    documented = 0
    for i, line in enumerate(lines):
        if line.startswith("["):
            section = line.strip("[]")
        elif section in {"camera", "laser", "arm"} and re.match(r"^\w+\s*=", line):
            j = i - 1
            while j >= 0 and re.match(r"^\w+\s*=", lines[j]):
                j -= 1  # a comment may document a short group of keys
            assert lines[j].startswith("#"), f"undocumented key: {line}"
            documented += 1
    fields = sum(
        len(dataclasses.fields(c)) for c in (V4L2CameraConfig, SerialLaserConfig, URArmConfig)
    )
    assert documented == fields + 4  # every field, the three backend keys, the laser's colour


def test_example_modbus_alternative_parses_when_uncommented() -> None:
    text = EXAMPLE.read_text()
    start = text.index('# backend = "modbus"')
    block = []
    for line in text[start:].splitlines():
        if not line.startswith("#"):
            break
        body = line[2:] if line.startswith("# ") else line[1:]
        if re.match(r"^\w+\s*=", body):
            block.append(body)
    cell = parse("[laser]\n" + "\n".join(block))
    assert isinstance(cell.laser.settings, ModbusLaserConfig)
    assert cell.laser.settings.host == "192.168.1.20"


def test_the_lasers_colour_is_read_for_any_backend() -> None:
    assert parse('[laser]\nbackend = "serial"\nport = "/dev/x"\n').laser_color == "red"
    green = parse('[laser]\nbackend = "serial"\nport = "/dev/x"\ncolor = "green"\n')
    assert green.laser_color == "green" and green.laser.settings.port == "/dev/x"
    assert parse('[laser]\nbackend = "sim"\ncolor = "blue"\n').laser_color == "blue"
    assert parse('[camera]\nbackend = "sim"\n').laser_color == "red"  # no laser section
    with pytest.raises(ConfigError, match=r"\[laser\]\.color: 'violet' is not one of red"):
        parse('[laser]\nbackend = "sim"\ncolor = "violet"\n')


def test_absent_sections_are_none() -> None:
    cell = parse('[laser]\nbackend = "serial"\nport = "/dev/ttyUSB1"\n')
    assert cell.camera is None and cell.arm is None
    assert cell.laser.settings.port == "/dev/ttyUSB1"


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ('[laser]\nport = "/dev/ttyUSB0"', "[laser].backend"),
        ('[laser]\nbackend = "gpio"', "[laser].backend"),
        ('[laser]\nbackend = "serial"', "[laser].port"),
        ('[laser]\nbackend = "serial"\nport = "/dev/x"\nbaud = 9600', "[laser].baud"),
        ('[laser]\nbackend = "serial"\nport = "/dev/x"\nbaudrate = "9600"', "[laser].baudrate"),
        ('[laser]\nbackend = "serial"\nport = "/dev/x"\nbaudrate = 0', "[laser].baudrate"),
        ('[laser]\nbackend = "serial"\nport = "/dev/x"\nretries = 1.5', "[laser].retries"),
        ('[laser]\nbackend = "serial"\nport = "/dev/x"\nexclusive = 1', "[laser].exclusive"),
        ('[laser]\nbackend = "modbus"\ntransport = "rtu"', "[laser].serial_port"),
        ('[camera]\nbackend = "v4l2"\npixel_format = "NV12"', "[camera].pixel_format"),
        ('[camera]\nbackend = "v4l2"\nfps = true', "[camera].fps"),
        ('[arm]\nbackend = "ur_rtde"\njoint_min_deg = [0, 0]', "[arm].joint_min_deg"),
        ('[arm]\nbackend = "ur_rtde"\nworkspace_max_mm = [1, "a", 3]', "[arm].workspace_max_mm[1]"),
        ('[arm]\nbackend = "ur_rtde"\ngripper_io = "wrist"', "[arm].gripper_io"),
        ("laser = 3", "[laser]"),
        ('[camera]\nbackend = "v4l2"\ntone_curve = "rec709"', "[camera].tone_curve"),
        ('[camera]\nbackend = "v4l2"\ntone_curve = "gamma:-1"', "[camera].tone_curve"),
        ('[camera]\nbackend = "v4l2"\ntone_curve = 2.2', "[camera].tone_curve"),
    ],
)
def test_wrong_or_missing_settings_name_the_key(text: str, key: str) -> None:
    assert error_key(text) == key


def test_integers_are_accepted_for_numbers() -> None:
    cell = parse('[camera]\nbackend = "v4l2"\nfps = 15\nexposure_ms = 2')
    assert cell.camera.settings.fps == 15.0 and isinstance(cell.camera.settings.fps, float)


def test_recorded_camera_paths_are_relative_to_the_config_file(tmp_path: Path) -> None:
    cfg = tmp_path / "cell.toml"
    cfg.write_text('[camera]\nbackend = "v4l2"\napi = "images"\ndevice = "rec/img_%03d.png"\n')
    cell = load_cell_config(cfg).devices
    assert cell.camera.settings.device == str(tmp_path / "rec" / "img_%03d.png")


def test_the_camera_tone_curve_is_the_cameras_and_a_table_is_relative_to_the_file(
    tmp_path: Path,
) -> None:
    """sRGB unless the section says otherwise; the camera reports its configured curve; a
    measured table is read at load, relative to the cell file, and a bad one names the key."""
    assert parse('[camera]\nbackend = "v4l2"').camera.settings.tone_curve == "srgb"
    gamma = parse('[camera]\nbackend = "v4l2"\ntone_curve = "gamma:2.2"').camera.settings
    assert V4L2Camera(gamma).tone_curve == "gamma:2.2"
    (tmp_path / "curve.json").write_text(json.dumps([(i / 255) ** 2 for i in range(256)]))
    cfg = tmp_path / "cell.toml"
    cfg.write_text('[camera]\nbackend = "v4l2"\ntone_curve = "curve.json"\n')
    assert load_cell_config(cfg).devices.camera.settings.tone_curve == str(tmp_path / "curve.json")
    (tmp_path / "curve.json").write_text(json.dumps([0.5] * 256))  # not increasing
    with pytest.raises(
        ConfigError, match=r"cell\.toml: \[camera\]\.tone_curve: .*increase"
    ) as info:
        load_cell_config(cfg)
    assert info.value.key == "[camera].tone_curve"  # type: ignore[attr-defined]


def test_missing_and_malformed_files_are_config_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="not found"):
        load_cell_config(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[laser\nbackend = ")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_cell_config(bad)


def test_factory_builds_unconnected_real_devices() -> None:
    devices = open_devices(tomllib.loads(EXAMPLE.read_text()), EXAMPLE)
    assert isinstance(devices.camera, V4L2Camera)
    assert isinstance(devices.laser, SerialLaser)
    assert isinstance(devices.arm, URArm)
    assert not any(d.is_connected for _, d in devices.items())
    modbus = parse('[laser]\nbackend = "modbus"\nhost = "10.0.0.5"').laser
    assert isinstance(open_laser(modbus), ModbusLaser)


def test_sim_settings_pass_through_to_the_sim_backend(monkeypatch: pytest.MonkeyPatch) -> None:
    from drivers.base import LaserSwitch

    class FakeSimLaser(LaserSwitch):
        name = "sim laser"
        is_connected = False

        def __init__(self, settings: dict) -> None:
            self.settings = settings

        def connect(self) -> None: ...
        def close(self) -> None: ...
        def set(self, on: bool, timeout_s: float | None = None) -> None: ...
        def state(self, timeout_s: float | None = None) -> bool:
            return False

    seen: dict = {}

    def fake_open_devices(sections: dict, base_dir: Path | None) -> dict:
        seen.update(sections=sections, base_dir=base_dir)
        return {k: FakeSimLaser(v) for k, v in sections.items()}

    module = types.ModuleType("sim_backend.devices")
    module.open_devices = fake_open_devices  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "sim_backend.devices", module)
    import sim_backend

    monkeypatch.setattr(sim_backend, "devices", module, raising=False)
    doc = tomllib.loads('[laser]\nbackend = "sim"\nscene = "table.toml"\nseed = 3\n')
    devices = open_devices(doc, Path("/etc/omnisort/cell.toml"))
    assert isinstance(devices.laser, FakeSimLaser)
    assert seen["sections"] == {"laser": {"scene": "table.toml", "seed": 3}}
    assert seen["base_dir"] == Path("/etc/omnisort")


def test_sim_backend_not_importable_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    import sim_backend

    monkeypatch.setitem(sys.modules, "sim_backend.devices", None)  # makes the import fail
    monkeypatch.delattr(sim_backend, "devices", raising=False)
    with pytest.raises(ConfigError, match=r"^\[arm\]\.backend: .*sim_backend\.devices"):
        open_devices(tomllib.loads('[arm]\nbackend = "sim"\n'))


@pytest.mark.parametrize(
    ("text", "key", "why"),
    [
        ('[camera]\nbackend = "sim"\nwidht = 640\n', "[camera].widht", "unknown key"),
        ('[laser]\nbackend = "sim"\nscnee = "sorting"\n', "[laser].scnee", "unknown key"),
        ('[arm]\nbackend = "sim"\nrealtime = "yes"\n', "[arm].realtime", "must be true or false"),
        ('[camera]\nbackend = "sim"\nwidth = -5\n', "[camera].width", "must be positive"),
    ],
)
def test_a_simulated_section_is_checked_when_the_file_loads(
    tmp_path: Path, text: str, key: str, why: str
) -> None:
    """A typo in a simulated device stops the load of the cell file (before any device or
    the simulator is built), not the first grab minutes later."""
    path = tmp_path / "cell.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    assert str(path) in str(info.value) and f"{key}: {why}" in str(info.value), str(info.value)
