"""A green laser on the cell, named in the cell file (`[laser] color = "green"`): the camera
and laser plane calibrated from one image of the two-sided target, then its line mapped, by
the CLI on that cell file, as for a red one. Without the cell file's colour the extractor looks
for red and finds no stripe: the colour is what makes it work."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from omnisort_hw.core.camera_io import save_camera_json
from omnisort_hw.core.camera_model import OcamModel
from tests.cli.test_extrinsics_cli import calibrate_cli, run_cli


@pytest.fixture(scope="module")
def green(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    from sim_backend.scene import Color, load_scene, sized
    from sim_backend.scene_images import render_scene, write_render

    out = tmp_path_factory.mktemp("green")
    scene = sized(load_scene("two_sided"), 960).replace(
        laser={"color": Color("green", (0.06, 1.0, 0.04)), "roll_deg": -6.0, "pitch_deg": 5.0}
    )
    image, truth = render_scene(scene, seed=3)
    write_render(out, "on", image, truth)
    save_camera_json(out / "camera.json", OcamModel.from_dict(truth["camera"]))
    (out / "cell.toml").write_text('[laser]\nbackend = "sim"\ncolor = "green"\n')
    return {"dir": out, "truth": out / "on.truth.json"}


def calibrate(d: Path, *config: str) -> tuple[int, dict]:
    proc = calibrate_cli(d, *config)
    return proc.returncode, json.loads(proc.stdout or proc.stderr or "{}")


def test_a_green_laser_named_in_the_cell_file_is_calibrated_and_mapped(green) -> None:
    d = green["dir"]
    truth = json.loads(green["truth"].read_text())
    code, reply = calibrate(d, "--config", str(d / "cell.toml"))
    assert code == 0, reply
    got = reply["result"]["parameters"]
    assert got["laser_pitch_deg"] == pytest.approx(truth["laser_plane"]["pitch_deg"], abs=0.05)
    assert got["laser_roll_deg"] == pytest.approx(truth["laser_plane"]["roll_deg"], abs=0.05)
    proc = run_cli(
        "map",
        str(d / "on.png"),
        "--system",
        str(d / "system.json"),
        "--config",
        str(d / "cell.toml"),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    assert len(json.loads(proc.stdout)["result"]["segments"]) >= 2


def test_without_its_colour_no_stripe_is_found(green) -> None:
    code, reply = calibrate(green["dir"])
    assert code != 0 and "laser" in json.dumps(reply).lower(), reply
