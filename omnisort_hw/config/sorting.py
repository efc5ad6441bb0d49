"""The `[sorting]` and `[registration]` sections of the cell file: parsed and validated once.

Every error is a `ConfigError` whose message starts with the key (`[sorting].approach_mm: ...`),
so `omnisort serve` can refuse to start naming it. Relative paths (`colors_file`) resolve
against the cell file's folder. `[sorting] from_scene = true` takes bins, obstacles, gripper,
cube size and region from the cell's scene when its backend knows one (the simulated cell);
the keys the section sets still win (`SortSection.resolve`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.config.location_settings import LOCATION_KEYS, location_changes
from omnisort_hw.config.registration_settings import FITS, RegistrationSettings
from omnisort_hw.core.checkerboard import BoardSpec
from omnisort_hw.core.choices import DEFAULT_BOARD
from omnisort_hw.core.cube_location import ColorTable
from omnisort_hw.core.extrinsics.system_calibration import SystemCalibration
from omnisort_hw.core.kinematics import get_model
from omnisort_hw.core.pick_planning import BinSpec, ObstacleSpec, SortConfig
from omnisort_hw.core.registration import pose_from_offset, tilt_prior_from_std
from omnisort_hw.errors import ConfigError, OmnisortError
from omnisort_hw.request_fields import Arg, args_of, check_given


@dataclass(frozen=True)
class RegistrationConfig:
    """`[registration]`: the floor board and its pose in B (see `core.registration`)."""

    board: BoardSpec
    offset: tuple[float, float, float, float, float, float]
    fit: str = "auto"  # "auto" (tilt prior from the calibration's std), "level" or "free"
    camera_height_mm: float = 1200.0

    @property
    def T_B_board(self) -> np.ndarray:
        return pose_from_offset(self.offset)

    def tilt_prior(self, calib: SystemCalibration) -> float | None:
        """The board-tilt prior for `register_robot` (see `core.registration`)."""
        return tilt_prior(self.fit, calib)

    def settings(self) -> dict[str, Any]:
        """The record as `[registration]` keys (what a command's flags are laid over)."""
        b = self.board
        return {
            "board": f"{b.cols}x{b.rows}",
            "square_mm": b.square_mm,
            "offset": list(self.offset),
            "fit": self.fit,
            "camera_height_mm": self.camera_height_mm,
        }


def tilt_prior(fit: str, calib: SystemCalibration) -> float | None:
    """ "level" -> 0, "free" -> None, "auto" -> the calibration's camera roll/pitch 1-sigma."""
    if fit not in FITS:
        raise ConfigError(f"registration fit must be one of {', '.join(FITS)}, got {fit!r}")
    if fit == "level":
        return 0.0
    if fit == "free":
        return None
    return tilt_prior_from_std(calib.std)


def _floats(value: object, n: int | None, key: str) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or (n is not None and len(value) != n):
        raise ConfigError(f"{key}: expected a list of {n or 'some'} numbers, got {value!r}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ConfigError(f"{key}: expected finite numbers, got {value!r}")
        out.append(float(v))
    return tuple(out)


def _number(
    data: Mapping[str, object], key: str, default: float, path: str, lo: float | None
) -> float:
    """A finite number (`default` when not given), at least `lo` unless it is None."""
    v = data.get(key, default)
    if (
        isinstance(v, int | float)
        and not isinstance(v, bool)
        and math.isfinite(v)
        and (lo is None or v >= lo)
    ):
        return float(v)
    bound = "" if lo is None else f" >= {lo}"
    raise ConfigError(f"{path}.{key}: expected a number{bound}, got {v!r}")


def _list(value: object, path: str) -> list[object]:
    """An array of tables (`[[sorting.bins]]`)."""
    if not isinstance(value, list):
        raise ConfigError(f"{path}: expected an array of tables, got {value!r}")
    return value


# `[sorting]` keys that are plain non-negative numbers, and every key the section knows.
_SORT_NUMBERS = (
    "tcp_offset_mm",
    "gripper_stroke_mm",
    "grasp_above_center_mm",
    "approach_mm",
    "lift_mm",
    "release_clearance_mm",
    "joint_speed_deg_s",
    "joint_accel_deg_s2",
    "linear_speed_mm_s",
    "linear_accel_mm_s2",
    "collision_margin_mm",
    "max_sigma_mm",
    "capture_tolerance_mm",
)
REGISTRATION_KEYS = frozenset(a.name for a in args_of(RegistrationSettings))
SORT_KEYS = {
    *_SORT_NUMBERS,
    *LOCATION_KEYS,
    "from_scene",
    "robot_model",
    "home_deg",
    "floor_z_B_mm",
    "workspace_B_mm",
    "use_laser",
    "bins",
    "obstacles",
    "colors",
}


def parse_sort_config(
    data: Mapping[str, object], base: SortConfig | None = None, base_dir: Path | None = None
) -> SortConfig:
    """`[sorting]` -> SortConfig (on top of `base`); a wrong key names `[sorting].key`."""
    path = "[sorting]"
    unknown = sorted(set(data) - SORT_KEYS)
    if unknown:
        raise ConfigError(
            f"{path}.{unknown[0]}: unknown key (known: {', '.join(sorted(SORT_KEYS))})"
        )
    cfg = base or SortConfig()
    changes: dict[str, Any] = {}
    for key in _SORT_NUMBERS:
        if key in data:
            changes[key] = _number(data, key, 0.0, path, 0.0)
    if "floor_z_B_mm" in data:
        changes["floor_z_B_mm"] = _number(data, "floor_z_B_mm", 0.0, path, -1e4)
    if "robot_model" in data:
        name = str(data["robot_model"])
        try:
            get_model(name)
        except (KeyError, ValueError) as exc:
            raise ConfigError(f"{path}.robot_model: {exc}") from None
        changes["robot_model"] = name
    if "home_deg" in data:
        changes["home_deg"] = _floats(data["home_deg"], 6, f"{path}.home_deg")
    if "workspace_B_mm" in data:
        r = _floats(data["workspace_B_mm"], 4, f"{path}.workspace_B_mm")
        if r[0] >= r[1] or r[2] >= r[3]:
            raise ConfigError(f"{path}.workspace_B_mm: expected [xmin, xmax, ymin, ymax], got {r}")
        changes["workspace_B_mm"] = r
    if "use_laser" in data:
        if not isinstance(data["use_laser"], bool):
            raise ConfigError(f"{path}.use_laser: expected true or false")
        changes["use_laser"] = data["use_laser"]
    if "bins" in data:
        bins = []
        for i, b in enumerate(_list(data["bins"], f"{path}.bins")):
            key = f"{path}.bins[{i}]"
            if not isinstance(b, Mapping) or "color" not in b or "center_B_mm" not in b:
                raise ConfigError(f"{key}: needs color and center_B_mm")
            bins.append(
                BinSpec(
                    str(b["color"]),
                    _floats(b["center_B_mm"], 2, f"{key}.center_B_mm"),  # type: ignore[arg-type]
                    _floats(b.get("size_mm", [240.0, 240.0, 120.0]), 3, f"{key}.size_mm"),  # type: ignore[arg-type]
                    _number(b, "yaw_B_deg", 0.0, key, None),
                )
            )
        changes["bins"] = tuple(bins)
    if "obstacles" in data:
        obs = []
        for i, o in enumerate(_list(data["obstacles"], f"{path}.obstacles")):
            key = f"{path}.obstacles[{i}]"
            if not isinstance(o, Mapping) or o.get("frame") not in ("S", "B"):
                raise ConfigError(f'{key}.frame: must be "S" or "B"')
            obs.append(
                ObstacleSpec(
                    str(o.get("name", f"obstacle {i}")),
                    str(o["frame"]),
                    _floats(o.get("center_mm"), 3, f"{key}.center_mm"),  # type: ignore[arg-type]
                    _floats(o.get("size_mm"), 3, f"{key}.size_mm"),  # type: ignore[arg-type]
                    _number(o, "yaw_deg", 0.0, key, None),
                )
            )
        changes["obstacles"] = tuple(obs)
    located = {k: data[k] for k in LOCATION_KEYS if k in data and k != "colors_file"}
    if "colors" not in data and "colors_file" in data:
        located["colors_file"] = data["colors_file"]
    changes |= location_changes(located, lambda a: f"{path}.{a.name}", base_dir=base_dir)
    if "colors" in data:
        colors = data["colors"]
        if not isinstance(colors, Mapping):
            raise ConfigError(f"{path}.colors: must be a table of colour names")
        changes["colors"] = ColorTable.from_mapping(colors, f"{path}.colors")
    return replace(cfg, **changes)


def parse_registration_config(data: Mapping[str, object]) -> RegistrationConfig:
    """`[registration]`: board = "9x6", square_mm, offset = [X, Y, Z, RX, RY, RZ], fit."""
    return registration_config(data, "[registration]", lambda a: f"[registration].{a.name}")


def registration_config(
    values: Mapping[str, object],
    where: str,
    label: Callable[[Arg], str],
    error: type[OmnisortError] = ConfigError,
    missing_hint: str = "",
) -> RegistrationConfig:
    """The record of `[registration]` values checked against `RegistrationSettings`; each
    problem an `error` (ConfigError for the file, InputError for flags) that starts with the
    key as `label` gives it (`[registration].square_mm`, or `--square`). `where`: what the
    values came from, for an unknown key; `missing_hint`: where else a missing one is given."""
    declared = {a.name: a for a in args_of(RegistrationSettings)}
    unknown = sorted(set(values) - set(declared))
    if unknown:
        known = ", ".join(sorted(declared))
        raise error(f"{where}.{unknown[0]}: unknown key (known: {known})")
    checked = check_given(RegistrationSettings, values, where, label, error)
    for name in ("square_mm", "offset"):
        if name not in checked:
            arg = declared[name]
            raise error(f"{label(arg)} is needed{missing_hint}: {arg.help}")
    try:
        board = BoardSpec.parse(checked.get("board", DEFAULT_BOARD), checked["square_mm"])
    except ValueError as exc:
        raise error(f"{label(declared['board'])}: {exc}") from None
    x, y, z, rx, ry, rz = checked["offset"]
    return RegistrationConfig(
        board,
        (x, y, z, rx, ry, rz),
        checked.get("fit", "auto"),
        checked.get("camera_height_mm", 1200.0),
    )


# `[sorting]` keys that set a differently named field of SortConfig.
_FIELD_OF_KEY = {"colors_file": "colors"}


@dataclass(frozen=True)
class SortSection:
    """`[sorting]` as the file gives it: the parsed record, which fields the file sets, and
    whether the scene of the cell's backend supplies the rest (`from_scene`)."""

    config: SortConfig
    given: frozenset[str] = frozenset()
    from_scene: bool = False

    def resolve(self, scene_config: SortConfig | None) -> SortConfig:
        """The record to sort with: the section itself, or with `from_scene` the scene's
        record (`scene_config`, None when the backend knows no scene) with the file's keys."""
        if not self.from_scene:
            return self.config
        if scene_config is None:
            raise ConfigError(
                "[sorting].from_scene: only with a backend that knows its scene (backend = sim)"
            )
        return replace(scene_config, **{k: getattr(self.config, k) for k in self.given})


def parse_sort_section(data: object, base_dir: Path | None = None) -> SortSection:
    """`[sorting]` -> SortSection; relative `colors_file` against `base_dir`."""
    if not isinstance(data, Mapping):
        raise ConfigError("[sorting]: must be a table")
    section = dict(data)
    from_scene = section.pop("from_scene", False)
    if not isinstance(from_scene, bool):
        raise ConfigError("[sorting].from_scene: expected true or false")
    cfg = parse_sort_config(section, None, base_dir)
    given = frozenset(_FIELD_OF_KEY.get(k, k) for k in section)
    return SortSection(cfg, given, from_scene)
