"""The cell file is loaded once into one typed record; every section is validated at start,
with the file and the key in the message, and relative paths resolve against its folder."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from omnisort_hw.cell.cell import Cell, CellDevices
from omnisort_hw.config.cell import CellConfig, load_cell_config
from omnisort_hw.errors import ConfigError
from omnisort_hw.pipeline.calibration_store import CalibrationStore

EXAMPLE = Path(__file__).resolve().parents[2] / "deploy" / "cell.example.toml"
COLORS = "[colors]\nred = [[0, 8, 100, 255, 50, 255]]\nteal = [[80, 100, 100, 255, 50, 255]]\n"


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(text)
    return path


def test_the_example_file_loads_into_every_section() -> None:
    cfg = load_cell_config(EXAMPLE)
    assert cfg.path == EXAMPLE.resolve()
    assert cfg.devices.camera is not None and cfg.devices.arm is not None
    assert cfg.sorting is not None and cfg.sorting.config.bins
    assert cfg.registration is not None and cfg.registration.board.cols == 9
    assert cfg.target.kind == "two-sided" and cfg.target.separation_mm is not None


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[sorting]\napproch_mm = 100\n", "[sorting].approch_mm"),
        ("[sorting]\nhome_deg = [1, 2]\n", "[sorting].home_deg"),
        ("[sorting]\nfrom_scene = 1\n", "[sorting].from_scene"),
        ("[sorting]\ncolors_file = 'missing.toml'\n", "[sorting].colors_file"),
        ("[registration]\nsquare_mm = 40\n", "[registration].offset"),
        (
            "[registration]\nsquare_mm = 40\noffset = [0,0,0,0,0,0]\nfit = 'x'\n",
            "[registration].fit",
        ),
        # Found by typing the parsed tables as `object`: each was a raw TypeError or ValueError.
        ("[sorting]\nbins = 'red'\n", "[sorting].bins"),
        (
            "[[sorting.bins]]\ncolor = 'red'\ncenter_B_mm = [0, 0]\nyaw_B_deg = 'west'\n",
            "[sorting].bins[0].yaw_B_deg",
        ),
        ("[sorting]\nobstacles = 3\n", "[sorting].obstacles"),
        ("[sorting.colors]\nred = 5\n", "[sorting].colors.red"),
        ("[sorting]\ncolors = 'red'\n", "[sorting].colors"),
        ("[target]\nkind = 'round'\n", "[target].kind"),
        ("[target]\nkind = 2\n", "[target].kind"),
        ("[target]\nseparation_mm = 1.2924\n", "[target].separation_mm"),
        ("[target]\nseparation_mm = 'wide'\n", "[target].separation_mm"),
        ("[target]\nseperation_mm = 1292.4\n", "[target].seperation_mm"),
        ("[plc]\nport = 502\n", "[plc]"),
        ("[service]\nport = -1\n", "[service]"),
    ],
)
def test_a_bad_key_names_the_file_and_the_key(tmp_path: Path, text: str, key: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_cell_config(path)
    assert str(path) in str(info.value) and key in str(info.value), str(info.value)


def test_relative_colors_file_resolves_against_the_file_from_any_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "conf").mkdir()
    (tmp_path / "conf" / "colours.toml").write_text(COLORS)
    path = tmp_path / "conf" / "cell.toml"
    path.write_text('[sorting]\ncolors_file = "colours.toml"\ncube_size_mm = 80\n')
    monkeypatch.chdir("/")  # as under systemd, without WorkingDirectory
    cfg = load_cell_config(path)
    assert cfg.sorting is not None
    assert cfg.sorting.config.colors.names() == ["red", "teal"]
    assert cfg.sorting.given == {"colors", "cube_size_mm"}


def test_from_scene_without_a_scene_stops_the_cell_at_start(tmp_path: Path) -> None:
    cfg = CellConfig.from_mapping({"sorting": {"from_scene": True}})
    store = CalibrationStore(state_dir=tmp_path / "state")
    with pytest.raises(ConfigError, match=r"\[sorting\]\.from_scene"):
        Cell(CellDevices(), store, config=cfg)
    # Without [sorting] the cell starts; a sort then says what is missing.
    Cell(CellDevices(), store, config=CellConfig.from_mapping({}))


def test_serve_refuses_to_start_on_a_bad_sorting_key(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        f'[storage]\nstate_dir = "{tmp_path / "state"}"\n[logging]\nlog_dir = "{tmp_path}"\n'
        "[sorting]\nlift_mm = 200\nlfit_mm = 200\n",
    )
    proc = subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", "serve", "--config", str(path), "--port", "0"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd="/",
    )
    assert proc.returncode != 0
    assert "[sorting].lfit_mm" in proc.stderr and str(path) in proc.stderr, proc.stderr
    assert not (tmp_path / "state").exists()  # nothing opened, nothing written
