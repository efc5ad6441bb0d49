"""Shared fixtures: the third-party reference images and a scratch directory."""

from __future__ import annotations

from pathlib import Path

import pytest

PROJECT_ROOT = Path(__file__).resolve().parent.parent
REFERENCE_DIR = PROJECT_ROOT.parent / "shared" / "reference" / "unity"


@pytest.fixture(scope="session")
def reference_dir() -> Path:
    """`../shared/reference/unity`, or a skip with the reason when this checkout has none."""
    if not REFERENCE_DIR.is_dir():
        pytest.skip(f"third-party reference images not found at {REFERENCE_DIR}")
    return REFERENCE_DIR
