"""`omnisort extrinsics calibrate` and `omnisort map` on rendered and third-party images."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from omnisort_hw.core.camera_io import save_camera_json
from omnisort_hw.core.camera_model import OcamModel

pytest.importorskip("pybullet")


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "omnisort_hw.cli", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A tilted two-sided scene at 960 px with the laser on and off, and its camera.json."""
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene, write_render

    out = tmp_path_factory.mktemp("ext")
    scene = sized(load_scene("two_sided"), 960).replace(
        camera={"roll_deg": 4.0, "pitch_deg": -3.0, "yaw_deg": 6.0},
        laser={"roll_deg": -6.0, "pitch_deg": 5.0},
    )
    image, truth = render_scene(scene, seed=3)
    write_render(out, "on", image, truth)
    off, _ = render_scene(scene, seed=3, laser_on=False)
    cv2.imwrite(str(out / "off.png"), off)
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    blue = (hsv[..., 0] > 95) & (hsv[..., 0] < 130) & (hsv[..., 1] > 120)
    painted = image.copy()
    painted[cv2.dilate(blue.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0] = (200, 200, 200)
    cv2.imwrite(str(out / "no_markers.png"), painted)
    cv2.imwrite(str(out / "small.png"), cv2.resize(image, (640, 640)))
    save_camera_json(out / "camera.json", OcamModel.from_dict(truth["camera"]))
    return {"dir": out, "truth": out / "on.truth.json"}


def calibrate_cli(d: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """`extrinsics calibrate` of `d`'s on.png with its camera.json and the truth's separation,
    into d/system.json (`extra`: more arguments)."""
    truth = json.loads((d / "on.truth.json").read_text())
    return run_cli(
        "extrinsics",
        "calibrate",
        str(d / "on.png"),
        "--camera",
        str(d / "camera.json"),
        "--target",
        "two-sided",
        "--separation",
        str(truth["target"]["separation_mm"]),
        "--out",
        str(d / "system.json"),
        "--json",
        *extra,
    )


def test_calibrate_and_map_a_rendered_image(rendered: dict[str, Path]) -> None:
    d = rendered["dir"]
    out = d / "system.json"
    proc = calibrate_cli(d)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)["result"]
    truth = json.loads(rendered["truth"].read_text())
    assert result["method"] == "joint"
    got = result["parameters"]
    assert got["cam_roll_deg"] == pytest.approx(truth["camera_rotation"]["roll_deg"], abs=0.05)
    assert got["laser_pitch_deg"] == pytest.approx(truth["laser_plane"]["pitch_deg"], abs=0.05)
    system = json.loads(out.read_text())
    assert system["image"]["sha256"] and system["laser_plane"]["distance_mm"] > 0
    # The picture beside system.json: the image with what was detected and fitted drawn over
    # it (the image's pixel coordinates kept), then the legend column.
    assert result["overlay_png"] == str(d / "system_overlay.png")
    source, pic = cv2.imread(str(d / "on.png")), cv2.imread(result["overlay_png"])
    assert pic is not None and pic.shape[0] == source.shape[0] and pic.shape[1] > source.shape[1]
    changed = np.any(pic[:, : source.shape[1]] != source, axis=2)
    assert 0.002 < changed.mean() < 0.2  # features and lines drawn, the image still there
    proc = run_cli("map", str(d / "on.png"), "--system", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["result"]["overlay_png"] == str(d / "on_map_overlay.png")
    map_pic = cv2.imread(str(d / "on_map_overlay.png"))
    # image | square top view | legend, the image's height
    assert map_pic.shape[0] == source.shape[0] and map_pic.shape[1] > 2 * source.shape[1]
    segs = json.loads(proc.stdout)["result"]["segments"]
    # The two walls' laser lines; their nearest points are the walls' near ends.
    target = truth["target"]
    half, near = target["separation_mm"] / 2, target["walls"][0]["inner_face_origin_mm"][1]
    want = float(np.hypot(half, near))
    assert len(segs) >= 2
    assert sorted(s["distance_mm"] for s in segs)[:2] == pytest.approx([want, want], rel=0.01)
    assert json.loads(proc.stdout)["result"]["laser_line"]["present"] is True
    # The laser off: no laser line, so nothing measured, and the verdict says why.
    proc = run_cli("map", str(d / "off.png"), "--system", str(out), "--json")
    dark = json.loads(proc.stdout)["result"]
    assert dark["points"] == 0 and dark["laser_line"]["present"] is False, dark
    assert dark["verdict"]["level"] == "fail", dark["verdict"]
    check = next(c for c in dark["verdict"]["checks"] if c["name"] == "laser line")
    assert "no laser line in the image" in check["advice"], check


@pytest.mark.parametrize(
    ("image", "extra", "message"),
    [
        ("off.png", [], "[no_laser_line]: "),
        ("no_markers.png", [], "marker"),
        ("small.png", [], "image is 640x640 but the camera model is for 960x960"),
        ("on.png", ["--target", "checkerboards"], "checkerboard"),
        ("on.png", ["--method", "method2"], "does not work with the two-sided target"),
        ("missing.png", [], "no such image file"),
        # The wall distance sets the laser plane's scale: never a default, never metres.
        ("on.png", ["--separation", "1.0845"], "looks like metres"),
        ("on.png", ["--separation", "52000"], "outside the plausible"),
        ("on.png", ["--separation", "nan"], "--separation must be a finite number within"),
    ],
)
def test_bad_input_fails_clearly_and_writes_nothing(
    rendered: dict[str, Path], image: str, extra: list[str], message: str
) -> None:
    d = rendered["dir"]
    out = d / f"bad-{image}-{len(extra)}.json"
    args = [
        "extrinsics",
        "calibrate",
        str(d / image),
        "--camera",
        str(d / "camera.json"),
        "--out",
        str(out),
    ]
    if "--target" not in extra:
        args += ["--target", "two-sided"]
        if "--separation" not in extra:
            args += ["--separation", "1084.5"]
    proc = run_cli(*args, *extra)
    assert proc.returncode != 0
    assert message.lower() in proc.stderr.lower(), proc.stderr
    assert not out.exists()
    assert not out.with_name(out.stem + "_overlay.png").exists()


def test_a_wall_target_without_its_measured_separation_is_refused(
    rendered: dict[str, Path],
) -> None:
    """No default wall distance: a forgotten `--separation` once gave a laser plane 16 % short."""
    d = rendered["dir"]
    out = d / "no-separation.json"
    proc = run_cli(
        "extrinsics",
        "calibrate",
        str(d / "on.png"),
        "--camera",
        str(d / "camera.json"),
        "--target",
        "two-sided",
        "--out",
        str(out),
    )
    assert proc.returncode != 0
    assert "--separation: required for the wall targets" in proc.stderr, proc.stderr
    assert not out.exists()


@pytest.mark.reference
def test_every_method_on_the_reference_images(reference_dir: Path, tmp_path: Path) -> None:
    from omnisort_hw.evaluation.reference_accuracy import intrinsics_model, run_reference

    runs = run_reference(reference_dir, intrinsics_model(reference_dir))
    params = {row: r.parameters for row, r in runs.items()}
    for key in (
        "cam_roll_deg",
        "cam_pitch_deg",
        "cam_yaw_deg",
        "laser_roll_deg",
        "laser_pitch_deg",
    ):
        values = [p[key] for p in params.values()]
        assert max(values) - min(values) <= 0.3, (key, values)
    walls = [
        params[m]["laser_distance_mm"] for m in ("joint", "paper", "method1", "joint_three_sided")
    ]
    assert max(walls) - min(walls) < 5.0


def test_blue_cubes_and_bins_are_not_taken_for_markers() -> None:
    """The sorting cell has blue cubes and bins near the walls and the laser low over the
    floor: the calibration image of a real cell, not a bare target."""
    from omnisort_hw.core.radiometry import ToneCurve
    from omnisort_hw.evaluation.table3 import truth_parameters
    from omnisort_hw.pipeline.extrinsics import calibrate_system
    from sim_backend.scene import load_scene, sized
    from sim_backend.scene_images import render_scene

    image, truth = render_scene(sized(load_scene("sorting"), 960), seed=1)
    model = OcamModel.from_dict(truth["camera"])
    calib = calibrate_system(
        image,
        model,
        "two-sided",
        "joint",
        separation_mm=truth["target"]["separation_mm"],
        tone=ToneCurve.parse(truth["render"]["tone_curve"]),  # the simulated camera's curve
    )
    want = truth_parameters(truth)
    got = calib.parameters()
    for key in want:
        assert got[key] == pytest.approx(want[key], abs=0.5 if key.endswith("_mm") else 0.03), key


def test_evaluate_table3_json(tmp_path: Path) -> None:
    """`omnisort evaluate table3` end to end on two small clean configurations: the documented
    JSON object, every row calibrated, and errors of the size the pixels allow."""
    data = tmp_path / "t3"
    proc = run_cli(
        "evaluate",
        "table3",
        "--n",
        "2",
        "--seed",
        "5",
        "--width",
        "960",
        "--data",
        str(data),
        "--json",
    )
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout)["result"]
    from omnisort_hw.core.extrinsics.system_calibration import PARAMETERS

    keys = set(PARAMETERS)
    assert set(result["methods"]) == {"joint", "paper", "method1", "method2", "joint_three_sided"}
    for name, row in result["methods"].items():
        assert row["failures"] == [] and row["n"] == 2, name
        assert set(row["mae"]) == keys and set(row["rmse"]) == keys and row["mean_time_s"] > 0
    # At 960 px a pixel is twice the angle it is at 1920 px: the 1920 px goal (0.03 deg, 1 mm)
    # doubled still has to hold for the wall methods on clean renders.
    for name in ("joint", "method1", "joint_three_sided"):
        mae = result["methods"][name]["mae"]
        assert max(v for k, v in mae.items() if k.endswith("_deg")) < 0.06, (name, mae)
        assert mae["laser_distance_mm"] < 2.0, (name, mae)
    assert 0 <= result["mapping"]["max_rel_error"] < 0.004
    assert (data / "dataset.json").is_file()


def test_a_wrong_target_description_is_a_config_error(
    rendered: dict[str, Path], tmp_path: Path
) -> None:
    """--target-file is checked before anything is measured: a misspelt key stops the command
    with the configuration exit status and names the file and the key."""
    example = Path(__file__).resolve().parents[2] / "deploy" / "target.example.toml"
    bad = tmp_path / "target.toml"
    bad.write_text(example.read_text().replace("border_height_mm = ", "border_hieght_mm = ", 1))
    d = rendered["dir"]
    proc = run_cli(
        "extrinsics",
        "calibrate",
        str(d / "on.png"),
        "--camera",
        str(d / "camera.json"),
        "--target",
        "two-sided",
        "--target-file",
        str(bad),
        "--out",
        str(tmp_path / "system.json"),
    )
    assert proc.returncode == 78, (proc.returncode, proc.stderr)
    assert "walls.left.border_hieght_mm: unknown key" in proc.stderr, proc.stderr
    assert str(bad) in proc.stderr
