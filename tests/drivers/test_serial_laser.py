"""Serial laser switch against a device emulator on a pseudo-terminal (real tty I/O)."""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator

import pytest

from drivers.errors import (
    BadReplyError,
    DeviceBusyError,
    DeviceConfigError,
    DeviceDisconnectedError,
    DeviceNotFoundError,
    DeviceTimeoutError,
)
from drivers.serial_laser import SerialLaser, SerialLaserConfig
from tests.drivers.contract import LaserSwitchContract
from tests.drivers.serial_emulator import SerialDeviceEmulator

pytestmark = pytest.mark.timeout(20)

TIMEOUT = 0.2


@pytest.fixture
def emulator() -> Iterator[SerialDeviceEmulator]:
    emu = SerialDeviceEmulator()
    yield emu
    emu.close()


def laser_for(emu: SerialDeviceEmulator, **overrides: object) -> SerialLaser:
    settings: dict[str, object] = {"port": emu.path, "timeout_s": TIMEOUT, "retries": 1}
    settings.update(overrides)
    return SerialLaser(SerialLaserConfig(**settings))  # type: ignore[arg-type]


class TestSerialLaserContract(LaserSwitchContract):
    @pytest.fixture
    def make_laser(self, emulator: SerialDeviceEmulator):
        return lambda: laser_for(emulator)


def test_switch_sends_the_configured_commands_and_reads_back(emulator) -> None:
    with laser_for(emulator) as laser:
        laser.on()
        assert emulator.laser_on is True
        laser.off()
        assert emulator.laser_on is False
    # connect queries once; each switch is command + query.
    assert emulator.received == ["LASER?", "LASER ON", "LASER?", "LASER OFF", "LASER?"]


def test_missing_port_is_device_not_found() -> None:
    laser = SerialLaser(SerialLaserConfig(port="/dev/ttyDOES_NOT_EXIST", timeout_s=TIMEOUT))
    with pytest.raises(DeviceNotFoundError, match="/dev/ttyDOES_NOT_EXIST"):
        laser.connect()
    assert not laser.is_connected


def test_port_held_by_another_process_is_busy(emulator) -> None:
    with laser_for(emulator):
        second = laser_for(emulator)
        with pytest.raises(DeviceBusyError, match=emulator.path):
            second.connect()


def test_silent_device_times_out_within_the_bound() -> None:
    with SerialDeviceEmulator(mode="silent") as emu:
        laser = laser_for(emu, retries=2)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match="did not answer") as info:
            laser.connect()
        elapsed = time.monotonic() - t0
    assert "3 attempt(s)" in str(info.value)
    assert 3 * TIMEOUT * 0.9 <= elapsed < 3 * TIMEOUT + 0.5
    assert emu.received == ["LASER?"] * 3
    assert not laser.is_connected


def test_binary_garbage_is_a_bad_reply() -> None:
    with SerialDeviceEmulator(mode="garbage") as emu:
        t0 = time.monotonic()
        with pytest.raises(BadReplyError, match="non-text bytes"):
            laser_for(emu).connect()
        assert time.monotonic() - t0 < 1.0


def test_unexpected_text_reply_is_a_bad_reply_naming_the_expectation(emulator) -> None:
    laser = laser_for(emulator, on_reply="LASER IS ON", off_reply="LASER IS OFF")
    with pytest.raises(BadReplyError, match="'LASER IS ON' or 'LASER IS OFF'"):
        laser.connect()


def test_wrong_acknowledgement_is_a_bad_reply(emulator) -> None:
    with laser_for(emulator, ack_reply="ACK") as laser, pytest.raises(BadReplyError, match="ACK"):
        laser.on()


def test_device_that_acknowledges_but_does_not_switch_is_caught() -> None:
    with SerialDeviceEmulator(mode="stuck") as emu, laser_for(emu) as laser:
        with pytest.raises(BadReplyError, match="reads back OFF"):
            laser.on()
        assert emu.laser_on is False


def test_late_answer_within_the_timeout_is_accepted() -> None:
    with SerialDeviceEmulator(mode="late", delay_s=TIMEOUT / 3) as emu, laser_for(emu) as laser:
        laser.on()
        assert laser.state() is True


def test_late_answer_after_the_timeout_is_a_timeout_and_not_misread_later() -> None:
    with SerialDeviceEmulator(mode="late", delay_s=TIMEOUT * 1.5) as emu:
        laser = laser_for(emu, retries=0)
        with pytest.raises(DeviceTimeoutError):
            laser.connect()
        # The device now answers at once; the stale late reply must be flushed, not misread.
        emu.mode = "normal"
        time.sleep(TIMEOUT)
        with laser:
            laser.on()
            assert laser.state() is True
            laser.off()
            assert laser.state() is False


def test_unplugged_device_is_a_disconnection_within_the_timeout(emulator) -> None:
    laser = laser_for(emulator)
    laser.connect()
    emulator.unplug()
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnectedError, match="went away"):
        laser.on()
    assert time.monotonic() - t0 < 1.0
    assert not laser.is_connected
    laser.close()


def test_calls_before_connect_are_a_typed_error(emulator) -> None:
    with pytest.raises(DeviceDisconnectedError, match="connect"):
        laser_for(emulator).state()


@pytest.mark.parametrize(
    ("key", "value"),
    [("baudrate", 0), ("timeout_s", 0.0), ("retries", -1), ("parity", "X"), ("port", "")],
)
def test_bad_settings_name_the_key(key: str, value: object) -> None:
    settings: dict[str, object] = {"port": "/dev/ttyUSB0", key: value}
    with pytest.raises(DeviceConfigError) as info:
        SerialLaserConfig(**settings)  # type: ignore[arg-type]
    assert info.value.key == f"[laser].{key}"
    assert f"[laser].{key}" in str(info.value)


def test_replugged_device_at_a_stable_link_is_reopened(tmp_path, caplog) -> None:
    """Like /dev/serial/by-id/...: the link is re-created by udev when the adapter comes back."""
    caplog.set_level(logging.INFO, logger="drivers")
    link = tmp_path / "usb-laser-if00"
    first = SerialDeviceEmulator()
    link.symlink_to(first.path)
    laser = SerialLaser(SerialLaserConfig(port=str(link), timeout_s=TIMEOUT, retries=0))
    laser.connect()
    laser.on()
    first.unplug()
    with pytest.raises(DeviceDisconnectedError):
        laser.off()
    with SerialDeviceEmulator() as second:
        link.unlink()
        link.symlink_to(second.path)
        laser.on()
        assert second.laser_on is True
        assert laser.state() is True
        laser.close()
    messages = [r.getMessage() for r in caplog.records]
    assert any("reopening the port" in m for m in messages)
    assert any("port reopened" in m for m in messages)
