"""The simulator is imported only by the commands that need it: `omnisort --help` and the
commands of a real cell (intrinsics, extrinsics on files, map, ctl, devices, review) never load
`sim_backend` or pybullet (whose import prints a build banner and costs a second)."""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

SIM_PREFIXES = ("sim_backend", "pybullet")

# Every top-level command except the ones that are the simulator (sim, demo, evaluate).
REAL_CELL_COMMANDS = (
    "intrinsics",
    "extrinsics",
    "map",
    "register-robot",
    "locate",
    "sort",
    "serve",
    "ctl",
    "review",
    "devices",
    "laser",
    "check",
)


def _loaded_sim_modules_after(code: str) -> list[str]:
    """Run `code` in a fresh interpreter; the simulator modules it left in sys.modules."""
    report = (
        f"import sys\nprint(sorted(m for m in sys.modules if m.startswith({SIM_PREFIXES!r})))\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code) + report],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return ast.literal_eval(proc.stdout.strip().splitlines()[-1])


def test_building_every_parser_imports_no_simulator() -> None:
    loaded = _loaded_sim_modules_after(
        """
        import omnisort_hw.cli
        omnisort_hw.cli.build_parser()
        """
    )
    assert loaded == []


def test_help_prints_no_pybullet_banner() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "--help"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "usage: omnisort" in proc.stdout
    assert "pybullet build time" not in proc.stdout + proc.stderr


@pytest.mark.parametrize("command", REAL_CELL_COMMANDS)
def test_real_cell_command_help_imports_no_simulator(command: str) -> None:
    loaded = _loaded_sim_modules_after(
        f"""
        from omnisort_hw.cli import main
        try:
            main([{command!r}, "--help"])
        except SystemExit as exc:
            assert exc.code == 0, exc.code
        """
    )
    assert loaded == []


def test_real_cell_commands_run_without_the_simulator(tmp_path: Path) -> None:
    """Commands that do their work (and fail in their typed way) load no simulator module."""
    loaded = _loaded_sim_modules_after(
        f"""
        import contextlib, io
        import cv2, numpy as np
        from omnisort_hw.cli import main
        blank = {str(tmp_path / "blank.png")!r}
        cv2.imwrite(blank, np.full((64, 64, 3), 128, np.uint8))
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
            codes = [
                main(["intrinsics", "calibrate", blank, "--square", "40",
                      "--out", {str(tmp_path / "camera.json")!r}]),
                main(["devices", "list"]),
                main(["ctl", "--port", "1", "--connect-timeout", "2", "status"]),
            ]
        assert codes == [2, 0, 3], (codes, out.getvalue())
        """
    )
    assert loaded == []


def test_the_sim_commands_still_load_the_simulator() -> None:
    """The other side of the rule: `omnisort sim scenes` imports it, banner kept off stdout."""
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "sim", "scenes"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "sorting" in proc.stdout
    assert "pybullet build time" not in proc.stdout
