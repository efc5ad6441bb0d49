"""The calibration target's kinds and the checks of its measured dimensions, shared by the
cell file's `[target]`, the CLI and the service: the wall distance sets the scale of every
extrinsic result, so it has no default and no unit guessing.

Also the target description file (TOML, documented in `deploy/target.example.toml`): the
target as its builder measured it, separation, each wall's border height and each marker's
centre and size (`core.target_layout`). Checked at load: a missing, misspelt, mistyped or
implausible field is a ConfigError naming the file and the field.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from omnisort_hw.config.toml_file import read_toml
from omnisort_hw.core.features import MARKER_NAMES
from omnisort_hw.core.target_layout import MarkerSpec, TargetLayout, WallSpec
from omnisort_hw.errors import ConfigError

SEPARATION_RANGE_MM = (100.0, 10000.0)
"""Inner wall distances a wall target can have, mm: a value below is a typo or metres."""


def separation_problem(value: object) -> str | None:
    """What is wrong with a measured inner wall distance `value` (mm), or None. The distance
    sets the scale of every extrinsic result, so there is no default and no unit guessing."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return f"expected a number of millimetres, got {value!r}"
    lo, hi = SEPARATION_RANGE_MM
    if 0 < value < 10:
        return (
            f"{value:g} looks like metres; give the inner distance between the walls in mm "
            f"(e.g. {value * 1000:g})"
        )
    if not lo <= value <= hi:
        return f"{value:g} mm is outside the plausible {lo:g}-{hi:g} mm of a wall target"
    return None


# ---- target description file ------------------------------------------------------------------

WALLS_FOR = {"two-sided": ("left", "right"), "three-sided": ("left", "right", "far")}
_MARKER_KEYS = ("along_mm", "height_mm", "size_mm")
_LENGTH_RANGE_MM = (0.0, 10000.0)


def _number(value: object, field: str, lo: float, hi: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"{field}: expected a number of millimetres, got {value!r}")
    if not lo <= value <= hi:
        raise ConfigError(f"{field}: {value:g} mm is outside {lo:g}-{hi:g} mm")
    return float(value)


def _table(doc: dict[str, Any], key: str, field: str) -> dict[str, Any]:
    if key not in doc:
        raise ConfigError(f"{field}: missing")
    value = doc[key]
    if not isinstance(value, dict):
        raise ConfigError(f"{field}: expected a table, got {value!r}")
    return value


def _unknown(table: dict[str, Any], known: tuple[str, ...], field: str) -> None:
    extra = sorted(set(table) - set(known))
    if extra:
        raise ConfigError(f"{field}.{extra[0]}: unknown key (known: {', '.join(known)})")


def _marker(table: dict[str, Any], field: str) -> MarkerSpec:
    _unknown(table, _MARKER_KEYS, field)
    for key in ("along_mm", "height_mm"):
        if key not in table:
            raise ConfigError(f"{field}.{key}: missing")
    along = _number(table["along_mm"], f"{field}.along_mm", *_LENGTH_RANGE_MM)
    height = _number(table["height_mm"], f"{field}.height_mm", *_LENGTH_RANGE_MM)
    size = table.get("size_mm")
    if size is not None:
        if not isinstance(size, list) or len(size) != 2:
            raise ConfigError(f"{field}.size_mm: expected [along, up] in mm, got {size!r}")
        size = tuple(_number(v, f"{field}.size_mm", 1.0, 1000.0) for v in size)
    return MarkerSpec(along, height, size)


def parse_target_description(doc: dict[str, Any], source: str) -> TargetLayout:
    """The target description `doc` (parsed TOML) as a TargetLayout; ConfigError naming the
    file and the field for anything missing, misspelt, of the wrong type or implausible."""
    try:
        return _parse(doc, source)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


def _parse(doc: dict[str, Any], source: str) -> TargetLayout:
    _unknown(doc, ("kind", "separation_mm", "walls"), "target")
    kind = doc.get("kind")
    if kind not in WALLS_FOR:
        raise ConfigError(f"target.kind: one of {', '.join(WALLS_FOR)}, got {kind!r}")
    if "separation_mm" not in doc:
        raise ConfigError("target.separation_mm: missing")
    problem = separation_problem(doc["separation_mm"])
    if problem:
        raise ConfigError(f"target.separation_mm: {problem}")
    walls_doc = _table(doc, "walls", "target.walls")
    names = WALLS_FOR[kind]
    _unknown(walls_doc, names, "target.walls")
    walls: dict[str, WallSpec] = {}
    for wall in names:
        field = f"walls.{wall}"
        w = _table(walls_doc, wall, field)
        _unknown(w, ("border_height_mm", "markers"), field)
        if "border_height_mm" not in w:
            raise ConfigError(f"{field}.border_height_mm: missing")
        border = _number(w["border_height_mm"], f"{field}.border_height_mm", *_LENGTH_RANGE_MM)
        markers_doc = _table(w, "markers", f"{field}.markers")
        _unknown(markers_doc, MARKER_NAMES, f"{field}.markers")
        markers = {}
        for name in MARKER_NAMES:
            m = _table(markers_doc, name, f"{field}.markers.{name}")
            markers[name] = _marker(m, f"{field}.markers.{name}")
        walls[wall] = WallSpec(border, markers)
    return TargetLayout(kind, float(doc["separation_mm"]), walls, source)


def load_target_description(path: str | Path) -> TargetLayout:
    """Read and check a target description file (TOML, `deploy/target.example.toml`)."""
    return parse_target_description(read_toml(path, "target description"), str(path))


def target_description_toml(layout: TargetLayout, header: str = "") -> str:
    """The text of a target description file for `layout` (what `load_target_description`
    reads back to the same layout)."""
    lines = [f"# {h}" for h in header.splitlines()]
    lines += [f'kind = "{layout.kind}"', f"separation_mm = {layout.separation_mm:.2f}"]
    for wall, spec in layout.walls.items():
        lines += ["", f"[walls.{wall}]", f"border_height_mm = {spec.border_height_mm:.2f}"]
        for name, m in spec.markers.items():
            lines += [
                "",
                f"[walls.{wall}.markers.{name}]",
                f"along_mm = {m.along_mm:.2f}",
                f"height_mm = {m.height_mm:.2f}",
            ]
            if m.size_mm is not None:
                lines.append(f"size_mm = [{m.size_mm[0]:.2f}, {m.size_mm[1]:.2f}]")
    return "\n".join(lines) + "\n"
