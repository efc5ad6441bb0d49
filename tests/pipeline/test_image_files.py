"""Image files cut short are refused by name before any detector sees them (a truncated JPEG
decodes into grey rows, which then read as "no board" or "found 1 blue marker")."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.cli import main
from omnisort_hw.errors import InputError
from omnisort_hw.pipeline.image_files import read_image


@pytest.fixture(scope="module")
def photo() -> np.ndarray:
    """A textured image (a JPEG of it has many entropy-coded bytes after its scan header)."""
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.integers(0, 255, (240, 320, 3), np.uint8), (5, 5), 0)
    return img


@pytest.mark.parametrize("suffix", [".jpg", ".png"])
def test_a_whole_file_reads_and_a_cut_one_is_refused(
    tmp_path: Path, photo: np.ndarray, suffix: str
) -> None:
    whole = tmp_path / f"whole{suffix}"
    assert cv2.imwrite(str(whole), photo)
    assert read_image(whole).shape == photo.shape
    cut = tmp_path / f"cut{suffix}"
    data = whole.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    with pytest.raises(InputError, match=rf"{cut.name}: truncated"):
        read_image(cut)


def test_a_jpeg_with_a_thumbnail_is_judged_by_its_main_scan(
    tmp_path: Path, photo: np.ndarray
) -> None:
    """An EXIF-style embedded thumbnail ends with its own end-of-image marker early in the
    file; the main image cut after it is still truncated, and the whole one is not."""
    ok, thumb = cv2.imencode(".jpg", cv2.resize(photo, (40, 30)))
    ok2, main_jpg = cv2.imencode(".jpg", photo)
    assert ok and ok2
    body = main_jpg.tobytes()
    app1 = b"Exif\x00\x00" + thumb.tobytes()
    segment = b"\xff\xe1" + (len(app1) + 2).to_bytes(2, "big") + app1
    whole = body[:2] + segment + body[2:]
    path = tmp_path / "exif.jpg"
    path.write_bytes(whole)
    assert read_image(path).shape == photo.shape
    path.write_bytes(whole[: len(whole) - 2000])
    with pytest.raises(InputError, match="truncated JPEG"):
        read_image(path)


def test_intrinsics_names_the_truncated_view(
    tmp_path: Path, photo: np.ndarray, capsys: pytest.CaptureFixture[str]
) -> None:
    views = []
    for i in range(3):
        views.append(tmp_path / f"view{i}.jpg")
        assert cv2.imwrite(str(views[-1]), photo)
    views[1].write_bytes(views[1].read_bytes()[:5000])
    argv = ["intrinsics", "calibrate", *map(str, views), "--out", str(tmp_path / "camera.json")]
    assert main([*argv, "--board", "9x6", "--square", "20"]) == 2
    err = capsys.readouterr().err
    assert "[bad_input]" in err and f"{views[1]}: truncated JPEG" in err, err
    assert not (tmp_path / "camera.json").exists()


@pytest.mark.reference
def test_every_third_party_photo_reads_whole_and_is_refused_cut(reference_dir: Path) -> None:
    """The end-of-image rule on files this project did not write (renders, camera JPEGs):
    no whole file is refused, and every one cut to 70 % is."""
    from omnisort_hw.pipeline.image_files import truncation_problem

    files = [
        p for p in reference_dir.parent.rglob("*") if p.suffix.lower() in {".jpg", ".jpeg", ".png"}
    ]
    assert len(files) >= 10
    for p in files:
        data = p.read_bytes()
        assert truncation_problem(data) is None, p
        assert truncation_problem(data[: len(data) * 7 // 10]) is not None, p
