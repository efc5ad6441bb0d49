"""The simulated devices of a cell hosted in a child process (`sim_backend.device_host`), seen
from the caller as `drivers.base` devices.

    made = open_devices({"camera": {...}, "laser": {...}, "arm": {...}}, base_dir)
    with made["camera"] as cam, made["arm"] as arm:
        frame = cam.grab()          # rendered and exposed in the child; the pixels come back
        arm.move_joints(q)          # stepped in the child; arm.stop() from any thread stops it

`open_devices` has the contract of `sim_backend.devices.open_devices` (the same keys, checked
the same way), but the pybullet world lives in the child: the caller's process never renders,
steps or exposes. Every method of the `drivers.base` interfaces is forwarded, and so is every
public method or attribute the simulated device has beyond them (`grab(with_truth=True)`,
`last_truth`, `clean_image()`, `direct_laser`, `gripper.held_body`, ...): a method added to a
simulated device or to an interface is forwarded without a change here. `device.cell` is the
hosted cell (`HostCell`): its scene (a copy taken at start), and its methods (`bump_camera`,
`release_stops`, `read("world.sim_time")`) run in the child. The sort's verifier
(`SimVerifier`) runs in the child too, next to the physics it watches.

The child lives while any of its devices is open: closing the last one closes the child
(within `device_host.CLOSE_TIMEOUT_S`). A dead or hung child makes every call raise
`DeviceDisconnectedError` / `DeviceTimeoutError` naming the device; `stop()` on a dead child
returns (nothing moves in a process that is gone).
"""

from __future__ import annotations

import abc
import contextlib
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from drivers.base import Arm, Camera, Frame, Gripper, LaserSwitch, MotionLimits
from drivers.errors import DeviceDisconnectedError
from sim_backend.device_host import SimHost
from sim_backend.devices import DEFAULT_SIM_GRAB_TIMEOUT_S, _check_settings
from sim_backend.sort_harness import SimScene

__all__ = ["HostCell", "HostedScene", "open_devices"]

STOP_TIMEOUT_S = 5.0


def _timeout_of(
    host: SimHost, sig: inspect.Signature, args: tuple[Any, ...], kwargs: dict[str, Any]
) -> float:
    """How long to wait for a forwarded call: its own `timeout_s` plus the host's margin, or
    the host's call timeout."""
    if "timeout_s" not in sig.parameters:
        return host.call_timeout_s
    try:
        bound = sig.bind(None, *args, **kwargs)
    except TypeError:
        return host.call_timeout_s
    bound.apply_defaults()
    value = bound.arguments.get("timeout_s")
    return host.call_timeout_s if value is None else float(value) + host.reply_margin_s


class _Remote:
    """Forwarding to one object of the child (`target`): calls and attribute reads and writes
    of what the child's object has beyond the local class."""

    _target = ""

    def __init__(self, host: SimHost, device: str) -> None:
        object.__setattr__(self, "_host", host)
        object.__setattr__(self, "_device", device)

    def _call(self, name: str, *args: Any, timeout_s: float | None = None, **kw: Any) -> Any:
        return self._host.call(self._device, self._target, "call", name, args, kw, timeout_s)

    def _get(self, name: str) -> Any:
        return self._host.call(self._device, self._target, "get", name)

    def _shape(self) -> dict[str, list[str]]:
        return self._host.shapes.get(self._target, {"methods": [], "attrs": []})

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        shape = self._shape()
        if name in shape["methods"]:

            def forward(*args: Any, **kwargs: Any) -> Any:
                t = kwargs.get("timeout_s")
                wait = None if t is None else float(t) + self._host.reply_margin_s
                return self._call(name, *args, timeout_s=wait, **kwargs)

            forward.__name__ = name
            return forward
        if name in shape["attrs"]:
            return self._get(name)
        raise AttributeError(f"{type(self).__name__} ({self._device}) has no attribute {name!r}")

    def __setattr__(self, name: str, value: object) -> None:
        if not name.startswith("_") and name in self._shape()["attrs"]:
            static = getattr(type(self), name, None)
            if not isinstance(static, property):
                self._host.call(self._device, self._target, "set", name, (value,))
                return
        object.__setattr__(self, name, value)


def _forward_interface(cls: type, base: type) -> type:
    """Give `cls` a forwarder for every public method and property of `base` (and its bases)
    that `cls` does not define itself, so a method added to an interface reaches the child."""
    own: set[str] = set()
    for k in cls.__mro__:
        if k not in base.__mro__:
            own.update(vars(k))
    for k in reversed(base.__mro__[:-1]):
        for name, member in vars(k).items():
            if name.startswith("_") or name in own:
                continue
            if isinstance(member, property):
                setattr(cls, name, _remote_property(name, member.fset is not None))
            elif inspect.isfunction(member):
                setattr(cls, name, _remote_method(name, member))
    abc.update_abstractmethods(cls)
    return cls


def _remote_method(name: str, fn: Any) -> Any:
    sig = inspect.signature(fn)

    def forward(self: _Remote, *args: Any, **kwargs: Any) -> Any:
        wait = _timeout_of(self._host, sig, args, kwargs)
        return self._call(name, *args, timeout_s=wait, **kwargs)

    forward.__name__ = name
    forward.__doc__ = fn.__doc__
    return forward


def _remote_property(name: str, settable: bool) -> property:
    def fget(self: _Remote) -> Any:
        return self._get(name)

    def fset(self: _Remote, value: object) -> None:
        self._host.call(self._device, self._target, "set", name, (value,))

    return property(fget, fset if settable else None)


class _HostedDevice(_Remote):
    """Life cycle shared by the hosted devices: connect and close in the child; the child ends
    when its last device closes."""

    def __init__(self, host: SimHost, kind: str) -> None:
        super().__init__(host, host.names[kind])
        object.__setattr__(self, "_target", kind)
        object.__setattr__(self, "_connected", 0)  # the host's start it connected in
        object.__setattr__(self, "_open", True)
        object.__setattr__(self, "_statics", {})
        host.users += 1

    @property
    def name(self) -> str:
        return self._device

    @property
    def is_connected(self) -> bool:
        """Connected in the child that runs now (not in one that was lost)."""
        return self._connected == self._host.starts and self._host.alive

    @property
    def cell(self) -> HostCell:
        """The hosted cell: its scene, and its methods run in the child."""
        return HostCell(self._host, self._device)

    @property
    def host_pid(self) -> int:
        """The PID of the child process that holds the simulated cell."""
        return self._host.pid

    def connect(self) -> None:
        if not self._open:
            raise DeviceDisconnectedError(
                f"{self._device} was closed and its simulated cell's process ended; open the "
                "devices again",
                device=self._device,
            )
        self._host.restart_if_lost()
        self._call("connect")
        object.__setattr__(self, "_connected", self._host.starts)

    def close(self) -> None:
        if not self._open:
            return
        object.__setattr__(self, "_connected", 0)
        object.__setattr__(self, "_open", False)
        host = self._host
        if host.alive:
            with contextlib.suppress(Exception):
                self._call("close")
        host.users -= 1
        if host.users <= 0:
            host.close()

    def _static(self, name: str) -> Any:
        """A value that does not change while the cell lives, read once."""
        if name not in self._statics:
            self._statics[name] = self._get(name)
        return self._statics[name]


class HostedCamera(_HostedDevice, Camera):
    """The simulated fisheye, rendering and exposing in the child."""

    @property
    def resolution(self) -> tuple[int, int]:
        return tuple(self._static("resolution"))

    @property
    def serial(self) -> str:
        return str(self._static("serial"))

    @property
    def tone_curve(self) -> str:
        return str(self._static("tone_curve"))

    def grab(self, timeout_s: float | None = None, **kwargs: Any) -> Frame:
        """A fresh frame rendered in the child (`with_truth=True` keeps its truth there, read
        with `last_truth`)."""
        limit = timeout_s if timeout_s is not None else self._static("grab_timeout_s")
        wait = float(limit or DEFAULT_SIM_GRAB_TIMEOUT_S) + self._host.reply_margin_s
        frame = self._call("grab", timeout_s, timeout_s=wait, **kwargs)
        if not isinstance(frame, Frame):  # pragma: no cover - the child always sends one
            frame = Frame.now(np.asarray(frame), 0)
        return frame


class HostedLaserSwitch(_HostedDevice, LaserSwitch):
    """The simulated laser's switch, in the child."""


class HostedGripper(_Remote, Gripper):
    """The arm's gripper, in the child."""

    _target = "gripper"


class HostedArm(_HostedDevice, Arm):
    """The simulated UR arm, stepping in the child. `stop()` is served by the child's reader
    thread as soon as it arrives, whatever else the child is doing."""

    def __init__(self, host: SimHost, kind: str = "arm") -> None:
        super().__init__(host, kind)
        gripper = HostedGripper(host, host.names[kind])  # type: ignore[abstract]  # _forward_interface fills its abstract methods after the class statement
        object.__setattr__(self, "_gripper", gripper)

    @property
    def limits(self) -> MotionLimits:
        return self._static("limits")

    @property
    def gripper(self) -> HostedGripper:
        return self._gripper

    def stop(self) -> None:
        if not self._host.alive:
            return  # the process that moved the arm is gone: nothing moves
        self._call("stop", timeout_s=STOP_TIMEOUT_S)

    def motion_trace(self) -> dict[str, Any]:
        """From the first call on, the child records the arm time (simulated seconds) of the
        last motion sample and of every `stop()`'s arrival: `{"samples", "last_sample",
        "stops", "now"}` (a stop's latency in the arm's own time, for tests and diagnosis)."""
        return self._host.call(self._device, "arm", "trace")


for _cls, _base in (
    (HostedCamera, Camera),
    (HostedLaserSwitch, LaserSwitch),
    (HostedGripper, Gripper),
    (HostedArm, Arm),
):
    _forward_interface(_cls, _base)


class HostCell(_Remote):
    """The simulated cell in the child: `scene` (copied at start) and `name` here, its methods
    and picklable attributes forwarded (`bump_camera`, `release_stops`, `protective_stop`);
    `read("world.sim_time")` reads a value along a dotted path."""

    _target = "cell"

    @property
    def scene(self) -> Any:
        return self._host.scene

    @property
    def name(self) -> str:
        return self._host.cell_name

    def read(self, path: str) -> Any:
        """A picklable value of the child's cell along a dotted path (truth for tests)."""
        return self._get(path)

    def scene_layout(self, arm: Any | None) -> HostedScene:
        """The cell's scene for the sorting pipeline (`sort_harness.scene_of` asks for it)."""
        return HostedScene(self, arm)


class HostedScene(SimScene):
    """`SimScene` of a hosted cell: layouts from the scene's copy, the verifier in the child."""

    def verifier(self) -> RemoteVerifier:  # type: ignore[override]
        if self.arm is None:
            return super().verifier()  # type: ignore[return-value]
        return RemoteVerifier(self.cell._host, self.arm.name)


class RemoteVerifier(_Remote):
    """A `SimVerifier` of the arm, in the child beside the physics it watches."""

    def __init__(self, host: SimHost, device: str) -> None:
        super().__init__(host, device)
        key, shape = host.call(device, "arm", "verifier")
        object.__setattr__(self, "_target", key)
        host.shapes[key] = shape

    def on_done(self, report: Any, loc: Any) -> None:
        """Fill `report` from the truth (the child fills a copy; its fields come back here)."""
        done = self._host.call(self._device, self._target, "done", "", (report, loc))
        report.__dict__.update(done.__dict__)


def open_devices(
    sections: dict[str, dict[str, Any]], base_dir: Path | None = None, **host: Any
) -> dict[str, Camera | LaserSwitch | Arm]:
    """The `backend = "sim"` devices of a cell configuration (keys of
    `sim_backend.devices.open_devices`), unconnected, on one simulated cell in a child process;
    `host` passes `call_timeout_s` / `reply_margin_s` to `SimHost`."""
    checked = {kind: _check_settings(kind, dict(s)) for kind, s in sections.items()}
    sim = SimHost(checked, base_dir, **host)
    made: dict[str, Camera | LaserSwitch | Arm] = {}
    kinds: dict[str, Callable[[SimHost, str], Camera | LaserSwitch | Arm]] = {
        "camera": HostedCamera,
        "laser": HostedLaserSwitch,
        "arm": HostedArm,
    }
    for kind in sim.kinds:
        made[kind] = kinds[kind](sim, kind)
    return made
