"""The `[sorting]` keys a cube location reads that `omnisort locate` may override, declared once
(`request_fields.param`): the cell file's parser (`config.sorting.parse_sort_config`) checks
them, and `locate` makes its flags from them, with the same bounds and the same messages.
Imports nothing heavy: the CLI reads it at every start."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omnisort_hw.errors import ConfigError, OmnisortError
from omnisort_hw.request_fields import Arg, args_of, check_given, param

CUBE_SIZE_RANGE_MM = (1.0, 1000.0)
"""A cube's edge the location can be asked for: from a sugar cube to a metre."""


@dataclass(frozen=True)
class LocationSettings:
    """What a location needs of `[sorting]` beyond its calibration, each key once with its
    type, unit, bounds and help (None: not given, the section's or the default)."""

    cube_size_mm: float | None = param(
        None,
        unit="mm",
        lo=CUBE_SIZE_RANGE_MM[0],
        hi=CUBE_SIZE_RANGE_MM[1],
        help="the cubes' edge (default 100)",
        flag="--cube-size",
    )
    colors_file: str | None = param(
        None,
        kind="path",
        help="the colour table (TOML or JSON; default the built-in red, green, blue, yellow)",
        flag="--color-table",
    )
    region_S_mm: tuple[float, ...] | None = param(
        None,
        length=4,
        lo=-1e5,
        hi=1e5,
        unit="mm",
        help="xmin,xmax,ymin,ymax: where cubes are looked for, on the floor in S (default: "
        "between the target's walls)",
        flag="--region",
    )


LOCATION_KEYS = frozenset(a.name for a in args_of(LocationSettings))


def location_changes(
    values: Mapping[str, object],
    label: Callable[[Arg], str],
    error: type[OmnisortError] = ConfigError,
    base_dir: Path | None = None,
) -> dict[str, Any]:
    """The `SortConfig` fields that `values` (of LOCATION_KEYS; None: not given) set, checked
    against `LocationSettings`: each problem an `error` (ConfigError for the file, InputError
    for flags) that starts with the key as `label` gives it (`[sorting].cube_size_mm`, or
    `--cube-size`). A relative colour table resolves against `base_dir`."""
    from omnisort_hw.core.cube_location import ColorTable

    declared = {a.name: a for a in args_of(LocationSettings)}
    changes: dict[str, Any] = {}
    for name, checked in check_given(LocationSettings, values, "[sorting]", label, error).items():
        arg = declared[name]
        if name == "colors_file":
            path = Path(checked)
            if base_dir is not None and not path.is_absolute():
                path = base_dir / path
            try:
                changes["colors"] = ColorTable.load(path)
            except ConfigError as exc:
                raise error(f"{label(arg)}: {exc}") from None
        elif name == "region_S_mm":
            r = tuple(float(v) for v in checked)
            if r[0] >= r[1] or r[2] >= r[3]:
                raise error(f"{label(arg)}: expected xmin < xmax and ymin < ymax, got {r}")
            changes[name] = r
        else:
            changes[name] = float(checked)
    return changes
