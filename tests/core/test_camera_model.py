"""The OCamCalib camera model: mapping accuracy, conventions, and its two file formats."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from omnisort_hw.core.camera_io import (
    export_ocamcalib,
    import_ocamcalib,
    load_camera_json,
    save_camera_json,
)
from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.errors import CalibrationFileError, InputError

# OCamCalib's own text export, written by hand from its format description: centre as
# (row, column) starting from 0, affine c d e, image size as (height, width).
OCAM_TXT = """#polynomial coefficients for the DIRECT mapping function (ocam_model.ss in MATLAB). These are used by cam2world

5 -2.713289e+02 0.000000e+00 1.484979e-03 -1.003385e-06 2.485264e-09

#polynomial coefficients for the inverse mapping function (ocam_model.invpol in MATLAB). These are used by world2cam

9 424.358326 287.161500 32.833283 29.037196 20.495091 11.393812 4.448984 1.727730 0.441593

#center: "row" and "column", starting from 0 (C convention)

383.186200 511.798500

#affine parameters "c", "d", "e"

1.000262 -0.000149 0.000115

#image size: "height" and "width"

768 1024
"""  # noqa: E501


def ocam_cam2world(
    row: np.ndarray,
    col: np.ndarray,
    ss: list[float],
    xc: float,
    yc: float,
    c: float,
    d: float,
    e: float,
) -> np.ndarray:
    """Transcription of OCamCalib's C `cam2world` (point2D[0] is the row)."""
    invdet = 1.0 / (c - d * e)
    xp = invdet * ((row - xc) - d * (col - yc))
    yp = invdet * (-e * (row - xc) + c * (col - yc))
    r = np.sqrt(xp * xp + yp * yp)
    zp = np.polynomial.polynomial.polyval(r, ss)
    n = np.sqrt(xp * xp + yp * yp + zp * zp)
    return np.stack([xp / n, yp / n, zp / n], axis=-1)


def ocam_world2cam(
    p: np.ndarray, invpol: list[float], xc: float, yc: float, c: float, d: float, e: float
) -> tuple[np.ndarray, np.ndarray]:
    """Transcription of OCamCalib's C `world2cam`; returns (row, column)."""
    norm = np.sqrt(p[:, 0] ** 2 + p[:, 1] ** 2)
    theta = np.arctan(p[:, 2] / norm)
    rho = np.polynomial.polynomial.polyval(theta, invpol)
    x = p[:, 0] / norm * rho
    y = p[:, 1] / norm * rho
    return x * c + y * d + xc, x * e + y + yc


@pytest.fixture(scope="module")
def fisheye() -> OcamModel:
    return OcamModel.equidistant(1920, 1920, 185.0)


@pytest.fixture(scope="module")
def stretched() -> OcamModel:
    return OcamModel.create(
        [-271.3289, 0.0, 1.484979e-03, -1.003385e-06, 2.485264e-09],
        (511.7985, 383.1862),
        (1.000262, -0.000149, 0.000115),
        (1024, 768),
    )


def _all_pixels(model: OcamModel, step: int = 7) -> np.ndarray:
    w, h = model.image_size
    uu, vv = np.meshgrid(np.arange(0, w, step, dtype=float), np.arange(0, h, step, dtype=float))
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


@pytest.mark.parametrize("name", ["fisheye", "stretched"])
def test_round_trip_within_a_hundredth_of_a_pixel_everywhere(name: str, request) -> None:
    model: OcamModel = request.getfixturevalue(name)
    uv = _all_pixels(model)
    rays = model.pixel_to_ray(uv)
    assert np.allclose(np.linalg.norm(rays, axis=1), 1.0)
    back = model.ray_to_pixel(rays)
    assert np.max(np.abs(back - uv)) <= 0.01
    assert model.inv_error_px <= 0.01


def test_equidistant_angle_is_proportional_to_radius(fisheye: OcamModel) -> None:
    uv = _all_pixels(fisheye, 11)
    theta = fisheye.angle_from_axis(fisheye.pixel_to_ray(uv))
    radius = np.hypot(uv[:, 0] - 959.5, uv[:, 1] - 959.5)
    k = 960.0 / np.deg2rad(92.5)
    assert np.max(np.abs(theta - radius / k)) < np.deg2rad(1e-4)


def test_field_of_view_beyond_180_degrees(fisheye: OcamModel) -> None:
    # The image circle edge is 92.5 deg from the axis: rays there point backwards (z < 0).
    edge = np.array([[959.5 + 955.0, 959.5], [959.5, 959.5 - 955.0]])
    rays = fisheye.pixel_to_ray(edge)
    assert np.all(rays[:, 2] < 0)
    assert np.allclose(fisheye.ray_to_pixel(rays), edge, atol=0.01)
    assert fisheye.fov_deg > 185.0
    behind = np.array([[1.0, 0.0, -0.02]])
    assert fisheye.in_view(behind)[0]
    assert not fisheye.in_view(np.array([[0.0, 0.0, -1.0]]))[0]


def test_axes_follow_opencv_convention(fisheye: OcamModel) -> None:
    centre = np.array([[959.5, 959.5]])
    assert np.allclose(fisheye.pixel_to_ray(centre), [[0, 0, 1]])
    right, below = fisheye.pixel_to_ray(np.array([[1200.0, 959.5], [959.5, 1200.0]]))
    assert right[0] > 0 and abs(right[1]) < 1e-12
    assert below[1] > 0 and abs(below[0]) < 1e-12


def test_import_matches_ocamcalib_reference_code(tmp_path: Path) -> None:
    path = tmp_path / "calib_results.txt"
    path.write_text(OCAM_TXT)
    model = import_ocamcalib(path)
    assert model.center_uv == (511.7985, 383.1862)  # (u, v) = (column, row)
    assert model.image_size == (1024, 768)  # (width, height)
    ss = [-2.713289e02, 0.0, 1.484979e-03, -1.003385e-06, 2.485264e-09]
    xc, yc, c, d, e = 383.1862, 511.7985, 1.000262, -0.000149, 0.000115
    rng = np.random.default_rng(1)
    uv = rng.uniform([0, 0], [1024, 768], size=(2000, 2))
    ours = model.pixel_to_ray(uv)
    ref = ocam_cam2world(uv[:, 1], uv[:, 0], ss, xc, yc, c, d, e)
    # OCamCalib's frame: x along rows, y along columns, z negative into the scene.
    assert np.allclose(ours, np.stack([ref[:, 1], ref[:, 0], -ref[:, 2]], axis=1), atol=1e-12)
    invpol = [float(x) for x in OCAM_TXT.split("\n")[6].split()[1:]]
    row, col = ocam_world2cam(ref, invpol, xc, yc, c, d, e)
    assert np.allclose(model.ray_to_pixel(ours), np.stack([col, row], axis=1), atol=0.01)


def test_export_then_import_round_trip(tmp_path: Path, stretched: OcamModel) -> None:
    path = export_ocamcalib(tmp_path / "calib_results.txt", stretched)
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    row, col = (float(x) for x in lines[2].split())
    assert (row, col) == (383.1862, 511.7985)
    assert lines[4].split() == ["768", "1024"]
    again = import_ocamcalib(path)
    assert np.array_equal(again.poly, stretched.poly)
    assert again.center_uv == stretched.center_uv and again.stretch == stretched.stretch
    # The exported inverse polynomial, run through OCamCalib's own world2cam, is accurate.
    invpol = [float(x) for x in lines[1].split()[1:]]
    uv = _all_pixels(stretched, 13)
    rays = stretched.pixel_to_ray(uv)
    c, d, e = stretched.stretch
    r, cl = ocam_world2cam(
        np.stack([rays[:, 1], rays[:, 0], -rays[:, 2]], axis=1), invpol, 383.1862, 511.7985, c, d, e
    )
    assert np.max(np.abs(np.stack([cl, r], axis=1) - uv)) <= 0.01


def test_import_refuses_bad_files(tmp_path: Path) -> None:
    bad = tmp_path / "short.txt"
    bad.write_text("#only a comment\n5 1 2 3\n")
    with pytest.raises(InputError, match=r"short\.txt"):
        import_ocamcalib(bad)
    swapped = tmp_path / "swapped.txt"
    lines = OCAM_TXT.split("\n")
    lines[2] = "5 -2.713289e+02 0.000000e+00 1.484979e-03 -1.003385e-06"
    swapped.write_text("\n".join(lines))
    with pytest.raises(InputError, match="leading count"):
        import_ocamcalib(swapped)


def test_camera_json_round_trip_and_errors(tmp_path: Path, fisheye: OcamModel) -> None:
    path = save_camera_json(tmp_path / "camera.json", fisheye, rms_px=0.12, images_used=["a.png"])
    model, meta = load_camera_json(path)
    assert meta["rms_px"] == 0.12 and meta["images_used"] == ["a.png"]
    uv = _all_pixels(fisheye, 97)
    assert np.allclose(model.pixel_to_ray(uv), fisheye.pixel_to_ray(uv), atol=1e-15)
    data = json.loads(path.read_text())
    del data["center_uv"]
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError, match="center_uv"):
        load_camera_json(path)
    path.write_text('{"poly": [1, 2')
    with pytest.raises(CalibrationFileError, match=r"camera\.json"):
        load_camera_json(path)
    with pytest.raises(CalibrationFileError, match="not found"):
        load_camera_json(tmp_path / "missing.json")


@pytest.mark.parametrize(
    ("key", "value", "field"),
    [
        ("poly", [float("nan"), 0.0, 1e-4], "'poly'"),
        ("center_uv", [float("nan"), 10.0], "'center_uv'"),
        ("center_uv", [5000.0, 10.0], "outside"),
        ("stretch", {"c": float("inf"), "d": 0.0, "e": 0.0}, "'stretch'"),
        ("image_size", [1920.5, 1920], "'image_size'"),
        ("image_size", [0, 1920], "'image_size'"),
        ("image_size", [float("inf"), 1920], "'image_size'"),
        ("poly", "abc", "camera model"),
    ],
)
def test_a_corrupt_camera_json_names_the_file_and_field(
    tmp_path: Path, fisheye: OcamModel, key: str, value: object, field: str
) -> None:
    """NaN, infinite, fractional or out-of-image values (Python's json writes and reads NaN)
    are refused with the file and the field, never fitted into a model that maps to NaN."""
    path = save_camera_json(tmp_path / "camera.json", fisheye)
    data = json.loads(path.read_text())
    data[key] = value
    path.write_text(json.dumps(data))
    with pytest.raises(CalibrationFileError) as info:
        load_camera_json(path)
    assert str(path) in str(info.value) and field in str(info.value), str(info.value)


def test_an_ocamcalib_file_with_nan_names_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "calib_results.txt"
    lines = OCAM_TXT.split("\n")
    row = next(i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#"))
    first = lines[row].split()
    lines[row] = " ".join([first[0], "nan", *first[2:]])
    bad.write_text("\n".join(lines))
    with pytest.raises(InputError, match=r"calib_results\.txt: 'poly' holds a NaN"):
        import_ocamcalib(bad)


def test_invalid_models_are_refused() -> None:
    with pytest.raises(InputError, match="a0 must be negative"):
        OcamModel.create([300.0, 0.0, -1e-3], (10, 10), image_size=(20, 20))
    with pytest.raises(InputError, match="singular"):
        OcamModel.create([-300.0, 0.0, 1e-4], (10, 10), (1.0, 1.0, 1.0), (20, 20))


@pytest.mark.parametrize("size_line", ["nan 1920", "inf 1920"])
def test_an_ocamcalib_file_with_a_non_finite_size_names_the_file(
    tmp_path: Path, size_line: str
) -> None:
    lines = OCAM_TXT.rstrip().split("\n")
    data_rows = [i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    lines[data_rows[-1]] = size_line
    bad = tmp_path / "calib_results.txt"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"calib_results\.txt: 'image_size'"):
        import_ocamcalib(bad)
