"""A run's `.rrd` file as PNG pictures, for machines without a display (`omnisort review --png`).

Every image entity of the recording (the last image logged to it) is written as a PNG with the
2D points and line strips logged under it drawn on top, in their logged colours: what rerun's
viewer shows in that image's view. The overlays the commands log (`extrinsics/overlay`) come
out as they are. 8-bit grey, RGB(A) and BGR(A) images are read; other encodings are skipped
and named.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from omnisort_hw.core.overlays import draw_dots, draw_polyline, write_png
from omnisort_hw.errors import InputError

# rerun's ColorModel (L, RGB, RGBA, BGR, BGRA) and ChannelDatatype U8 codes.
_TO_BGR = {
    1: cv2.COLOR_GRAY2BGR,
    2: cv2.COLOR_RGB2BGR,
    3: cv2.COLOR_RGBA2BGR,
    5: cv2.COLOR_BGRA2BGR,
}
_CHANNELS = {1: 1, 2: 3, 3: 4, 4: 3, 5: 4}
_U8 = 6


@dataclass
class Recorded:
    """What the recording holds for the pictures: the last image and 2D overlays per entity."""

    images: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> BGR
    points: dict[str, tuple[np.ndarray, np.ndarray, int]] = field(default_factory=dict)
    strips: dict[str, tuple[list[np.ndarray], np.ndarray]] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)  # entity -> why no picture


def _colours(values: Any, n: int) -> np.ndarray:
    """rerun's packed 0xRRGGBBAA colours as (n, 3) BGR (white when none were logged)."""
    packed = np.asarray(values if values else [0xFFFFFFFF], np.uint32)
    bgr = np.stack([(packed >> 8) & 255, (packed >> 16) & 255, packed >> 24], axis=1)
    return np.broadcast_to(bgr.astype(np.uint8), (n, 3)) if len(bgr) == 1 else bgr[:n]


def _last_row(column: Any) -> int | None:
    """Index of the last non-empty row of an arrow list column (None if none)."""
    for i in range(len(column) - 1, -1, -1):
        if column[i].is_valid and len(column[i].values):
            return i
    return None


def _last(column: Any) -> Any:
    """The last non-empty row of an arrow list column, as Python values (None if none)."""
    i = _last_row(column)
    return None if i is None else column[i].as_py()


def _last_array(column: Any) -> np.ndarray | None:
    """The last non-empty row of a list column of numbers, flattened to numpy (no copy into
    Python objects: an image row is millions of bytes)."""
    i = _last_row(column)
    if i is None:
        return None
    values = column[i].values
    while hasattr(values, "flatten"):
        values = values.flatten()
    return values.to_numpy(zero_copy_only=False)


def _image(data: np.ndarray, fmt: dict[str, Any], entity: str, rec: Recorded) -> None:
    model, dtype = fmt.get("color_model"), fmt.get("channel_datatype")
    if fmt.get("pixel_format") is not None or dtype != _U8 or model not in _CHANNELS:
        rec.skipped[entity] = "not an 8-bit grey/RGB(A)/BGR(A) image"
        return
    h, w = int(fmt["height"]), int(fmt["width"])
    data = np.asarray(data, np.uint8)
    if data.size != h * w * _CHANNELS[model]:
        rec.skipped[entity] = f"buffer of {data.size} bytes for a {w}x{h} image"
        return
    img = data.reshape(h, w, _CHANNELS[model]).copy()
    rec.images[entity] = cv2.cvtColor(img, _TO_BGR[model]) if model in _TO_BGR else img
    rec.skipped.pop(entity, None)


def read_recording(rrd_path: str | Path) -> Recorded:
    """Images, 2D points and line strips of an `.rrd` file, the last logged of each entity."""
    from rerun.chunk import RrdReader

    rec = Recorded()
    try:
        chunks = list(RrdReader(str(rrd_path)).stream())
    except Exception as exc:
        raise InputError(f"{rrd_path}: not a readable .rrd file ({exc})") from None
    for chunk in chunks:
        entity = str(chunk.entity_path)
        batch = chunk.to_record_batch()
        names = set(batch.schema.names)
        if {"Image:buffer", "Image:format"} <= names:
            data, fmt = (
                _last_array(batch.column("Image:buffer")),
                _last(batch.column("Image:format")),
            )
            if data is not None and fmt:
                _image(data, fmt[0], entity, rec)
        if "Points2D:positions" in names:
            flat = _last_array(batch.column("Points2D:positions"))
            pos = np.zeros((0, 2)) if flat is None else flat.astype(float).reshape(-1, 2)
            cols = _last(batch.column("Points2D:colors")) if "Points2D:colors" in names else None
            radii = _last(batch.column("Points2D:radii")) if "Points2D:radii" in names else None
            radius = round(float(radii[0])) if radii else 1
            rec.points[entity] = (pos, _colours(cols, len(pos)), max(0, radius))
        if "LineStrips2D:strips" in names:
            strips = _last(batch.column("LineStrips2D:strips")) or []
            cols = (
                _last(batch.column("LineStrips2D:colors"))
                if "LineStrips2D:colors" in names
                else None
            )
            lines = [np.asarray(s, float).reshape(-1, 2) for s in strips]
            rec.strips[entity] = (lines, _colours(cols, max(1, len(lines))))
    return rec


def pictures(rec: Recorded) -> dict[str, np.ndarray]:
    """Each image with the points and strips logged under its entity drawn on a copy."""
    out = {}
    for entity, image in rec.images.items():
        pic = image.copy()
        prefix = entity.rstrip("/") + "/"
        for child, (pts, cols, radius) in rec.points.items():
            if child.startswith(prefix):
                draw_dots(pic, pts, cols, radius)
        for child, (lines, cols) in rec.strips.items():
            if child.startswith(prefix):
                for k, line in enumerate(lines):
                    b, g, r = (int(c) for c in cols[min(k, len(cols) - 1)])
                    draw_polyline(pic, line, (b, g, r), max(1, round(pic.shape[1] / 1000)))
        out[entity] = pic
    return out


def picture_name(entity: str) -> str:
    """A file name for an entity path: `/extrinsics/image` -> `extrinsics_image.png`."""
    return (re.sub(r"[^A-Za-z0-9._-]+", "_", entity.strip("/")) or "root") + ".png"


def write_pictures(rrd_path: str | Path, folder: str | Path) -> tuple[list[Path], dict[str, str]]:
    """Write the recording's pictures into `folder` (made if needed); the paths written and
    the image entities skipped with the reason. InputError when the file holds no image."""
    rec = read_recording(rrd_path)
    pics = pictures(rec)
    if not pics:
        raise InputError(f"{rrd_path}: the recording holds no image to write")
    out = Path(folder)
    return [write_png(out / picture_name(e), p) for e, p in sorted(pics.items())], rec.skipped
