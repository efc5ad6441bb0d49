"""What ran a trial: the code's git revision, the package versions, the host (per process).

Computed once per process (they cannot change while it runs) and recorded in every row, so
rows from a cluster with mismatched workers can be told apart afterwards.
"""

from __future__ import annotations

import functools
import os
import platform
import socket
import subprocess
from importlib import metadata
from pathlib import Path

BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
# The packages whose versions decide a trial's numbers.
PACKAGES = ("omnisort-hw", "numpy", "scipy", "opencv-python-headless", "pybullet")
SOURCE = Path(__file__).resolve().parents[2]


@functools.cache
def git_revision() -> str | None:
    """HEAD of the checkout the package runs from ("+dirty" with uncommitted changes), or
    None for an installed copy without git."""
    try:
        rev = subprocess.run(
            ["git", "-C", str(SOURCE), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(SOURCE), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return rev + ("+dirty" if dirty else "")


@functools.cache
def package_versions() -> dict[str, str | None]:
    """Installed version of each package of PACKAGES (None when missing)."""
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def provenance() -> dict[str, object]:
    """This process's record: git revision, package versions, host, pid and the BLAS thread
    limits it runs under."""
    return {
        "git": git_revision(),
        "packages": package_versions(),
        "host": socket.gethostname(),
        "pid": os.getpid(),
        "blas_threads": {v: os.environ.get(v) for v in BLAS_THREAD_VARIABLES},
    }
