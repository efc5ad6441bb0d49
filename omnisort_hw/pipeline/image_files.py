"""Image files as the product reads them: decoded once, and refused with the file's name when
they are missing, unreadable or cut short. A truncated JPEG decodes without an error (libjpeg
fills the missing rows with grey and warns on stderr), and was then reported as "no board" or
"found 1 blue marker"; the end-of-image markers are checked here instead."""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np

from omnisort_hw.core.camera_model import OcamModel
from omnisort_hw.errors import InputError
from omnisort_hw.fileio import read_input_bytes

JPEG_SUFFIXES = frozenset({".jpg", ".jpeg", ".jpe"})


def truncation_problem(data: bytes) -> str | None:
    """Why the encoded image `data` is cut short, or None. JPEG: the last start-of-scan must
    be followed by an end-of-image marker (a thumbnail's EOI comes before the main scan);
    PNG: the IEND chunk must close the file."""
    if data[:3] == b"\xff\xd8\xff":
        if data.rfind(b"\xff\xd9") < data.rfind(b"\xff\xda"):
            return "truncated JPEG (no end-of-image marker after the last scan)"
    elif data[:8] == b"\x89PNG\r\n\x1a\n" and b"IEND" not in data[-64:]:
        return "truncated PNG (no IEND chunk at the end)"
    return None


def read_image(path: str | Path) -> np.ndarray:
    """The colour image at `path` (BGR, uint8), or an InputError naming the file."""
    p = Path(path)
    data = read_input_bytes(p, "an image file", InputError, "no such image file")
    problem = truncation_problem(data)
    if problem:
        raise InputError(f"{p}: {problem}; copy the file again")
    try:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:
        image = None
    if image is None or image.size == 0:
        raise InputError(f"{p}: not a readable image (unknown format or corrupt)")
    return image


def image_record(path: str | Path) -> dict[str, str]:
    """The image file's record in system.json and replies: its path and SHA-256."""
    p = Path(path)
    return {"path": str(p), "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}


def check_image_size(image: np.ndarray, model: OcamModel, source: str) -> None:
    """InputError naming `source` when the image is not the size the camera model is for."""
    size = (image.shape[1], image.shape[0])
    if size != tuple(model.image_size):
        raise InputError(
            f"{source}: image is {size[0]}x{size[1]} but the camera model is for "
            f"{model.image_size[0]}x{model.image_size[1]}"
        )
