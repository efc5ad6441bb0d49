"""camera.json and OCamCalib's calib_results.txt.

camera.json holds the model (OcamModel.to_dict) plus the calibration's record: RMS, images
used and rejected, standard deviations, date. calib_results.txt is OCamCalib's own text
export; it indexes the centre as (row, column) and lists the image size as (height, width),
so both are converted here and nowhere else.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.errors import CalibrationFileError, InputError
from omnisort_hw.fileio import atomic_write_bytes, atomic_write_json, read_calibration_json

MODEL_KEYS = (
    "model",
    "image_size",
    "center_uv",
    "stretch",
    "poly",
    "inv_poly",
    "theta_max_deg",
)


def camera_record(model: OcamModel, **meta: Any) -> dict[str, Any]:
    """The camera.json payload: the model's keys, then the calibration's record."""
    return {**model.to_dict(), **meta}


def save_camera_json(path: str | Path, model: OcamModel, **meta: Any) -> Path:
    """Write camera.json atomically (the previous version goes to history/)."""
    return atomic_write_json(path, camera_record(model, **meta))


def camera_from_record(data: dict[str, Any], source: str) -> OcamModel:
    """The OCam model of a camera.json record read from `source`; a malformed one is a
    CalibrationFileError naming it."""
    try:
        return OcamModel.from_dict(data, source=source)
    except InputError as exc:
        raise CalibrationFileError(str(exc)) from exc


def load_camera_json(path: str | Path) -> tuple[OcamModel, dict[str, Any]]:
    """Read camera.json; a missing, unreadable or malformed file is a CalibrationFileError."""
    p = Path(path)
    data = read_calibration_json(p, "camera")
    model = camera_from_record(data, str(p))
    model_only = {*MODEL_KEYS, "inv_error_px", "uncertainty"}
    meta = {k: v for k, v in data.items() if k not in model_only}
    return model, meta


_OCAM_HEADERS = (
    "#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). "
    "These are used by cam2world",
    "#polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB). "
    "These are used by world2cam",
    '#center: "row" and "column", starting from 0 (C convention)',
    '#affine parameters "c", "d", "e"',
    '#image size: "height" and "width"',
)


def export_ocamcalib(path: str | Path, model: OcamModel) -> Path:
    """Write OCamCalib's calib_results.txt (centre as row, column; size as height, width)."""
    invpol = model.ocam_inverse_for_export()
    cu, cv = model.center_uv
    c, d, e = model.stretch
    w, h = model.image_size

    def fmt(values: Any) -> str:
        return " ".join(f"{float(x):.15e}" for x in values)

    blocks = [
        f"{len(model.poly)} {fmt(model.poly)}",
        f"{len(invpol)} {fmt(invpol)}",
        fmt([cv, cu]),
        fmt([c, d, e]),
        f"{h} {w}",
    ]
    text = "".join(f"{hdr}\n\n{body} \n\n" for hdr, body in zip(_OCAM_HEADERS, blocks, strict=True))
    return atomic_write_bytes(path, text.encode("ascii"))


def import_ocamcalib(path: str | Path) -> OcamModel:
    """Read OCamCalib's calib_results.txt into an OcamModel.

    The file's inverse polynomial is checked against its forward one (an inconsistent file is
    refused) but not used: the inverse is refitted to this project's tolerance.
    """
    p = Path(path)
    try:
        lines = p.read_text(encoding="ascii", errors="strict").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{p}: cannot read OCamCalib file ({exc})") from exc
    rows = [
        (n + 1, ln.split())
        for n, ln in enumerate(lines)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    names = (
        "direct polynomial",
        "inverse polynomial",
        "centre (row column)",
        "affine c d e",
        "image size (height width)",
    )
    if len(rows) < 5:
        raise InputError(
            f"{p}: OCamCalib file has {len(rows)} data lines, expected 5 ({', '.join(names)})"
        )

    def numbers(i: int, count: int | None = None) -> list[float]:
        lineno, tokens = rows[i]
        try:
            vals = [float(t) for t in tokens]
        except ValueError as exc:
            raise InputError(f"{p}:{lineno}: {names[i]}: not a number ({exc})") from exc
        if count is not None and len(vals) != count:
            raise InputError(f"{p}:{lineno}: {names[i]}: expected {count} numbers, got {len(vals)}")
        return vals

    def counted(i: int) -> list[float]:
        lineno, _ = rows[i]
        vals = numbers(i)
        n = int(vals[0]) if vals and vals[0] == int(vals[0]) else -1
        if n < 1 or len(vals) != n + 1:
            raise InputError(
                f"{p}:{lineno}: {names[i]}: leading count does not match the coefficients"
            )
        return vals[1:]

    ss = counted(0)
    invpol = counted(1)
    row_c, col_c = numbers(2, 2)
    c, d, e = numbers(3, 3)
    height, width = numbers(4, 2)
    try:
        model = OcamModel.create(ss, (col_c, row_c), (c, d, e), (width, height))
    except InputError as exc:
        raise InputError(f"{p}: {str(exc).removeprefix('camera model: ')}") from exc
    theta = np.linspace(0.0, model.theta_max, 2001)
    file_rho = np.polynomial.polynomial.polyval(theta - np.pi / 2, invpol)
    model_rho = np.polynomial.polynomial.polyval(theta, model.inv_poly)
    mismatch = float(np.max(np.abs(file_rho - model_rho)))
    if not mismatch <= 1.0:  # NaN coefficients compare False both ways
        raise InputError(
            f"{p}: inverse polynomial disagrees with the direct one by {mismatch:.2f} px "
            "(file edited by hand, or lines swapped?)"
        )
    return model
