"""The tables of measured figures in README.md and docs/, generated from results.json.

    python -m benchmarks.figures           # check: exit 1 and name the stale blocks
    python -m benchmarks.figures --write   # rewrite the blocks from results.json

A block sits between `<!-- figures:NAME -->` and `<!-- /figures -->`; everything between
the markers is generated, so a table can never drift from the record (`tests/test_figures.py`
checks every block). A single figure in a sentence is `<!-- fig:PATH|FMT -->VALUE<!-- /fig -->`
(`benchmarks/prose.py`), rewritten by the same `render`. The check also lists every measured
figure typed by hand (`prose.check`, the rule in `tests/test_prose_figures.py`). Published
figures (the paper's Table 3) are constants of the literature.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchmarks import prose
from benchmarks.figures_common import ANGLES, PARAM_HEADS, PARAMS
from benchmarks.figures_common import table as _table
from benchmarks.figures_real_light import (
    real_light,
    real_light_camera,
    stripe_effects,
    table3_effects,
    table3_effects_captures,
)
from benchmarks.figures_uncertainty import uncertainty, uncertainty_rows

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DOCUMENTS = (ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")))
ALLOWLIST = ROOT / "docs" / "figures_allowlist.txt"
BLOCK = re.compile(r"(<!-- figures:(\w+) -->\n)(.*?)(<!-- /figures -->)", re.S)

TABLE3_ROWS = (
    ("joint", "**joint** (two-sided)"),
    ("paper", "paper (two-sided)"),
    ("method1", "method1 (three-sided)"),
    ("joint_three_sided", "joint (three-sided)"),
    ("method2", "method2 (checkerboards)"),
)
# The paper's Table 3 (MAE, their simulator; no laser distance figure comparable to ours).
PUBLISHED = (
    ("published: proposed", (0.13, 0.05, 0.06, 0.09, 0.14), 28.39),
    ("published: method 1", (0.12, 0.06, 0.06, 0.12, 0.16), 33.99),
    ("published: method 2", (0.15, 0.11, 0.09, 0.08, 0.29), 25.41),
)


def _machine(r: dict[str, Any]) -> str:
    m = r.get("machine", {})
    return f"{m.get('cores', '?')}-core {m.get('cpu', '?')}, Python {m.get('python', '?')}"


def table3(r: dict[str, Any]) -> str:
    t = r["table3"]
    rows: list[list[Any]] = []
    for images in ("clean", "degraded"):
        for key, label in TABLE3_ROWS:
            mae = t[f"{images}_{key}_mae"]
            secs = t[f"{images}_{key}_mean_time_s"]
            maes = [f"{mae[p]:.4f}" for p in ANGLES]
            rows.append([label, images, *maes, f"{mae['laser_distance_mm']:.3f}", f"{secs:.2f}"])
        # The same images with the camera's tone curve ignored (the extraction before it
        # modelled the curve), where the run recorded it.
        for key, label in TABLE3_ROWS:
            mae = t.get(f"{images}_linear_assumed_{key}_mae")
            if mae is not None:
                maes = [f"{mae[p]:.4f}" for p in ANGLES]
                d = f"{mae['laser_distance_mm']:.3f}"
                rows.append([label, f"{images}, curve ignored", *maes, d, "–"])
    for label, maes, secs in PUBLISHED:
        rows.append([label, "their simulator", *maes, "–", secs])
    head = ["method (target)", "images", *PARAM_HEADS.split(" | "), "time s"]
    fails = sum(t[f"{i}_{k}_failures"] for i in ("clean", "degraded") for k, _ in TABLE3_ROWS)
    n_degraded = t.get("degraded_configurations", t["configurations"])
    note = (
        f"\n{t['configurations']} configurations clean, {n_degraded} degraded (seed {t['seed']}); "
        f"failed calibrations: {fails}. Mapping check, worst relative distance error: "
        f"{t['clean_mapping_max_rel_error_pct']:.3f} % clean, "
        f"{t['degraded_mapping_max_rel_error_pct']:.3f} % degraded (published: 0.5 %).\n"
    )
    return _table(head, rows) + note


def reference(r: dict[str, Any]) -> str:
    e = r["extrinsics"]
    names = {
        "joint": "joint (two_sided_target.png)",
        "paper": "paper (two_sided_target.png)",
        "method1": "method1 (three_sided_target.png)",
        "method2": "method2 (checkerboard_b.jpg)",
        "joint_three_sided": "joint (three_sided_target.png)",
    }
    rows = []
    for key, label in names.items():
        p = e.get(f"reference_{key}")
        if isinstance(p, dict):
            rows.append([label, *(f"{p[k]:.3f}" for k in ANGLES), f"{p['laser_distance_mm']:.1f}"])
    spread = e.get("reference_max_disagreement_deg", {})
    worst = max(spread.items(), key=lambda kv: kv[1]) if spread else ("-", float("nan"))
    return _table(["method (image)", *PARAM_HEADS.split(" | ")], rows) + (
        f"\nLargest disagreement between the methods: {worst[1]:.3f}° ({worst[0]}).\n"
    )


def reference_errors(r: dict[str, Any]) -> str:
    """Signed errors on the authors' renders against the exact scene: the camera's tone curve
    ignored (tone ignored), the symmetric paper target assumed (symmetric target), and the
    scene's target description used (described: what the product does)."""
    e = r["extrinsics"]
    before, after = e["reference_errors_before"], e["reference_errors_after"]
    symmetric = e.get("reference_errors_symmetric_target", {})
    names = {
        "joint": "joint (two-sided)",
        "paper": "paper (two-sided)",
        "method1": "method1 (three-sided)",
        "joint_three_sided": "joint (three-sided)",
        "method2": "method2 (checkerboards)",
        "two_minus_three_sided_joint": "two-sided − three-sided joint",
    }

    def signed(p: dict[str, float]) -> list[str]:
        out = [f"{p[k]:+.3f}".replace("-", "−") for k in ANGLES]
        return [*out, f"{p['laser_distance_mm']:+.2f}".replace("-", "−")]

    def unsigned(p: dict[str, float]) -> list[str]:
        return [*(f"{p[k]:.3f}" for k in ANGLES), f"{p['laser_distance_mm']:.2f}"]

    std = after.get("reported_std", {})
    rows = []
    for key, label in names.items():
        if key in before and key in after:
            rows.append([label, "tone ignored", *signed(before[key])])
            if key in symmetric:
                rows.append(["", "symmetric target", *signed(symmetric[key])])
            rows.append(["", "described", *signed(after[key])])
            if key in std:
                rows.append(["", "its own σ (described)", *unsigned(std[key])])
    return _table(["method (image)", "", *PARAM_HEADS.split(" | ")], rows)


def reference_features(r: dict[str, Any]) -> str:
    """The extracted borders and stripes against the authors' scene, through its own camera."""
    feats = r["extrinsics"].get("reference_features_vs_scene", {})
    rows = []
    for image, walls in feats.items():
        for wall, f in walls.items():
            b, la = f["border"], f["laser"]
            rows.append(
                [
                    f"{image.split('_')[0]}-sided, {wall}",
                    f"{b['offset_mm']:+.2f}".replace("-", "−"),
                    f"{b['slope_deg']:+.3f}".replace("-", "−"),
                    f"{la['offset_mm']:+.2f}".replace("-", "−"),
                    f"{la['slope_deg']:+.3f}".replace("-", "−"),
                    f"{la['rms_about_line_mm']:.2f}",
                ]
            )
    head = [
        "image, wall",
        "border above scene's, mm",
        "border slope, °",
        "stripe above true line, mm",
        "stripe slope against it, °",
        "stripe scatter about its line, mm",
    ]
    return _table(head, rows)


def intrinsics(r: dict[str, Any]) -> str:
    i = r["intrinsics"]
    f, u, peer = i["fisheye2"], i["unity"], i["peer_py_ocamcalib"]
    pf, p2 = peer["fisheye2"], peer["second_lens_1032x778"]
    ref, ren = f["refinements"], i["renders_refinements"]

    def wall(x: dict[str, Any]) -> str:
        return (
            f"{x['calibration_s']:.2f} s wall, {x['calibration_cpu_s']:.2f} s CPU "
            f"(load {x['load_average_1min']:.1f} on 2 cores)"
        )

    def corners(x: dict[str, Any]) -> str:
        return (
            f"**{x['rms_px_2d']:.4f} px** ({x['corners_rejected']} of "
            f"{x['corners_used'] + x['corners_rejected']} corners dropped; "
            f"{x['rms_px_2d_no_corner_dropped']:.4f} px with none dropped)"
        )

    def versus_truth(kind: str) -> str:
        return ", ".join(
            f"{m} {ren[kind][m]['corner_error_vs_truth_rms_px']:.4f}"
            for m in ("saddle", "plane", "auto")
        )

    rows = [
        [
            "real `fisheye2` (748x480, 8x6, 117 mm): images used",
            f"**{f['images_used']} of {f['images_given']}**",
            f"{pf['images_used']} of {pf['of']}",
            f"{f['opencv_images_found']} found",
        ],
        [
            "`fisheye2` RMS, 2D distance",
            corners(f),
            f"{pf['rms_px_2d']:.3f} px",
            f"{f['opencv_fisheye_rms_px_2d']:.4f} px",
        ],
        ["`fisheye2` whole calibration", wall(f), f"~{pf['time_s']} s", ""],
        [
            "`fisheye2` refinement forced: saddle / plane / per image (RMS px)",
            " / ".join(f"{ref[m]['rms_px_2d']:.4f}" for m in ("saddle", "plane", "auto")),
            "",
            "",
        ],
        [
            "second real lens (1032x778, 8x6, 32.5 mm), kept out of the repository",
            "checked elsewhere",
            f"{p2['images_used']} of {p2['of']}, {p2['rms_px_2d']:.3f} px, ~{p2['time_s']} s",
            "diverges",
        ],
        [
            "Unity renders `a1..a9` (1920x1920, 9x6, 116 mm): images used",
            f"**{u['images_used']} of {u['images_given']}**",
            "",
            f"{u['opencv_images_found']}",
        ],
        ["Unity RMS, 2D distance", corners(u), "", f"{u['opencv_fisheye_rms_px_2d']:.4f} px"],
        [
            "Unity focal length (a0)",
            f"{u['focal_px']:.2f} px ({u['focal_minus_opencv_px']:+.2f} px from OpenCV)",
            "",
            f"{u['opencv_focal_px']:.2f} px",
        ],
        ["Unity whole calibration", wall(u), "", ""],
        ["renders, clean: corner error vs truth (RMS px)", versus_truth("clean"), "", ""],
        ["renders, degraded: corner error vs truth (RMS px)", versus_truth("degraded"), "", ""],
        ["pixel → ray, 1 million points", f"{i['pixel_to_ray_1M_ms']:.0f} ms", "", ""],
        ["ray → pixel, 1 million points", f"{i['ray_to_pixel_1M_ms']:.0f} ms", "", ""],
        ["pixel → ray → pixel, worst error", f"{i['round_trip_max_error_px']:.1e} px", "", ""],
    ]
    head = ["measured", "omnisort", "py-OCamCalib (reference)", "OpenCV fisheye, same images"]
    return _table(head, rows)


def extrinsics_speed(r: dict[str, Any]) -> str:
    e = r["extrinsics"]
    rows = [
        [
            "one 1920x1920 calibration (extraction + joint solve)",
            f"{e['calibration_1920_joint_s']:.3f} s "
            f"({e['calibration_speedup_vs_published_28_39s']:.0f}x faster than the published "
            "28.39 s)",
        ],
        [
            "one 1920x1920 laser map (stripe + mapping), one core",
            f"{e['map_1920_frame_ms_one_core']:.1f} ms",
        ],
    ]
    return _table(["measured", "time"], rows)


def kinematics(r: dict[str, Any]) -> str:
    k = r["kinematics"]
    err_mm = max(k[f"{m}_fkik_max_pos_err_mm"] for m in ("ur3e", "ur5e", "ur10e"))
    err_rad = max(k[f"{m}_fkik_max_rot_err_rad"] for m in ("ur3e", "ur5e", "ur10e"))
    rows = [
        ["IK, UR5e, 8 branches", f"{k['ik_ur5e_poses_per_s_8_branches']:,} poses/s"],
        ["FK, UR5e", f"{k['fk_ur5e_poses_per_s']:,} poses/s"],
        ["FK(IK) round trip, worst over UR3e/5e/10e", f"{err_mm:.1e} mm, {err_rad:.1e} rad"],
        [
            "joint move plan / linear move plan",
            f"{k['joint_move_plan_ms']} ms / {k['linear_move_plan_ms']} ms",
        ],
        ["collision checks", f"{k['collision_check_samples_per_s']:,} samples/s"],
    ]
    return _table(["measured", "result"], rows)


def sorting(r: dict[str, Any]) -> str:
    s = r["sorting"]
    rows = []
    for cal in ("truth", "perturbed"):
        rows.append(
            [
                f"{cal} calibration, {s[f'{cal}_scenes']} scenes (seed {s['seed']}, "
                f"{s['width_px']} px)",
                f"**{s[f'{cal}_sorted_ok']}/{s[f'{cal}_cubes']}**",
                s[f"{cal}_collisions"],
                f"{s[f'{cal}_mean_position_error_mm']:.2f} / "
                f"{s[f'{cal}_max_position_error_mm']:.2f}",
                f"{s[f'{cal}_mean_position_error_B_mm']:.2f}",
                f"{s[f'{cal}_mean_registration_error_mm']:.2f} mm, "
                f"{s[f'{cal}_mean_registration_error_deg']:.3f}°",
                f"**{s[f'{cal}_picks_per_minute']:.2f}**",
                f"{s[f'{cal}_motion_s_per_pick']:.2f} / {s[f'{cal}_lower_bound_s_per_pick']:.2f} s",
                f"{s[f'{cal}_gripper_s_per_pick']:.2f} s",
                f"{s[f'{cal}_wait_s_per_pick']:.3f} s",
            ]
        )
    head = [
        "random scenes (3–6 cubes, camera within ±10°)",
        "in the right bin",
        "collisions",
        "cube error in S, mean / max mm",
        "in B, mean mm",
        "registration (mean)",
        "picks per minute",
        "motion / planned lower bound per pick",
        "gripper per pick",
        "computation waited for per pick",
    ]
    plan = (
        f"\nPlanning alone ({s['planning_plans']} picks of 8 random scenes, CPU time on one "
        f"core): mean {s['planning_plan_ms_mean']:.0f} ms, p95 {s['planning_plan_ms_p95']:.0f} "
        f"ms, max {s['planning_plan_ms_max']:.0f} ms per pick.\n"
    )
    return _table(head, rows) + plan


def service(r: dict[str, Any]) -> str:
    """One row per long command the clients polled through (`during_<name>.*` keys), or the
    single run of an older record (`long_command`, `latency_*` at the top level)."""
    v = r["service"]
    runs = sorted({k.split(".", 1)[0] for k in v if k.startswith("during_")})
    prefixes = [f"{name}." for name in runs] or [""]
    if "idle.latency_p99_ms" in v:
        prefixes.insert(0, "idle.")
    rows = []
    for pre in prefixes:
        command = v.get(f"{pre}long_command", "none (idle, same clients)")
        if not isinstance(command, str):
            command = json.dumps(command)
        rows.append(
            [
                command,
                v.get(f"{pre}devices", v["devices"]),
                v["clients"],
                v[f"{pre}status_requests"],
                v[f"{pre}missed_replies"],
                f"{v[f'{pre}latency_median_ms']:.1f} ms",
                f"{v[f'{pre}latency_p99_ms']:.1f} ms",
                f"{v[f'{pre}latency_max_ms']:.1f} ms",
            ]
        )
    head = ["long command", "devices", "clients", "status requests", "missed", "median", "p99"]
    return _table([*head, "max"], rows)


def virtual_cell(r: dict[str, Any]) -> str:
    """The real drivers against the virtual cell (`benchmarks/bench_virtual_cell.py`)."""
    v = r["virtual_cell"]
    rows = [
        [
            "RTDE round trip (ur-rtde `setStandardDigitalOut` until "
            "`actual_digital_output_bits` shows it), median / p99",
            f"{v['rtde_round_trip_median_ms']:.2f} ms / {v['rtde_round_trip_p99_ms']:.2f} ms",
        ],
        [
            "control-script command handshake (`moveJ` async: command → done → clear), median",
            f"{v['command_handshake_median_ms']:.2f} ms",
        ],
        ["joint error after `moveJ` (5 random moves), max", f"{v['movej_joint_error_max_deg']}°"],
        ["TCP error after `moveL` (5 random moves), max", f"{v['movel_tcp_error_max_mm']:.3g} mm"],
        [
            "UR driver connect (worker process, three ur-rtde interfaces, script upload)",
            f"{v['ur_driver_connect_s']:.2f} s",
        ],
        [
            "protective stop during a move → `safety_stop`",
            f"{v['protective_stop_to_safety_stop_s']:.3f} s",
        ],
        [
            f"stalled controller → `{v['stall_error']}` (`state_timeout_s` 0.5)",
            f"{v['stall_to_error_s']:.3f} s",
        ],
        [f"controller killed mid-move → `{v['killed_error']}`", f"{v['killed_to_error_s']:.3f} s"],
        [
            "`omnisort serve` + `deploy/cell.virtual.toml` sort: cubes in their bin, collisions",
            f"{v['sort_cubes_in_their_bin']}/{v['sort_cubes']}, {v['sort_collisions']}",
        ],
        [
            "time per pick (sort step / cubes placed; real-time controller, `[sorting]` speeds "
            "120°/s, 300 mm/s)",
            f"{v['sort_seconds_per_pick']:.2f} s",
        ],
    ]
    return _table(["figure", "value"], rows)


def stream_stripe(r: dict[str, Any]) -> str:
    """What the camera stream's compression costs the laser stripe, against the lossless frame."""
    v = r["virtual_cell"]
    rows: list[list[Any]] = [
        ["lossless PNG (reference)", v["stripe_points_lossless"], 0, 0, 0],
    ]
    for key, label in (
        ("q80", "JPEG quality 80, 4:2:0"),
        ("q95", "JPEG quality 95, 4:2:0"),
        ("q100_444", "JPEG quality 100, 4:4:4 (near-lossless, `deploy/cell.virtual.toml`)"),
    ):
        rows.append(
            [
                label,
                v[f"stripe_{key}_points"],
                f"{v[f'stripe_{key}_median_px']:.3f} px",
                f"{v[f'stripe_{key}_p95_px']:.3f} px",
                v[f"stripe_{key}_image_max_abs_diff"],
            ]
        )
    return _table(["stream", "stripe points", "median", "p95", "largest pixel difference"], rows)


def soak(r: dict[str, Any]) -> str:
    s = r["soak"]
    rows = [
        ["length", f"{s['soak_s'] / 60:.0f} min"],
        [
            "jobs / commands / `status` polls",
            f"{s['jobs']:,} / {s['work_requests']:,} / {s['status_requests']:,}",
        ],
        ["abuse rounds", s["abuse_rounds"]],
        ["errors (not ok, or no reply)", s["errors"]],
        [
            "RSS, second tenth -> last tenth",
            f"{s['rss_early_mb']:.1f} -> {s['rss_late_mb']:.1f} MB ({s['rss_drift_pct']:+.2f} %)",
        ],
        ["open descriptors", "–".join(str(v) for v in s["fds_min_max"])],
        [
            "largest `.rrd` / log directory",
            f"{s['rrd_largest_mb']:.2f} MB (limit "
            f"{s['rrd_file_limit_mb']}) / {s['rrd_dir_max_mb']:.1f} MB (limit "
            f"{s['rrd_total_limit_mb']})",
        ],
        ["`status` p99 / max", f"{s['status_p99_ms']:.0f} / {s['status_max_ms']:.0f} ms"],
        ["exit code on SIGTERM", s["service_exit_code"]],
    ]
    return _table(["soak", "measured"], rows) + f"\nMachine: {_machine(r)}.\n"


def summary(r: dict[str, Any]) -> str:
    t, e, i, s, k = r["table3"], r["extrinsics"], r["intrinsics"], r["sorting"], r["kinematics"]
    vc = r["virtual_cell"]
    j, jd = t["clean_joint_mae"], t["degraded_joint_mae"]
    rows = [
        [
            "fisheye intrinsics, real photographs (fisheye2) / Unity renders",
            f"{i['fisheye2']['images_used']}/{i['fisheye2']['images_given']} images, RMS "
            f"{i['fisheye2']['rms_px_2d']:.3f} px (py-OCamCalib "
            f"{i['peer_py_ocamcalib']['fisheye2']['rms_px_2d']:.3f} px) / "
            f"{i['unity']['images_used']}/{i['unity']['images_given']}, "
            f"{i['unity']['rms_px_2d']:.3f} px",
            "[calibration](docs/calibration.md)",
        ],
        [
            "camera + laser from one image (joint), MAE worst angle, clean / degraded",
            f"{max(j[a] for a in ANGLES):.4f}° / {max(jd[a] for a in ANGLES):.4f}° "
            f"(published: 0.05–0.14°)",
            "[calibration](docs/calibration.md)",
        ],
        [
            "one calibration / one laser map, 1920 px",
            f"{e['calibration_1920_joint_s']:.3f} s / {e['map_1920_frame_ms_one_core']:.1f} ms",
            "[calibration](docs/calibration.md)",
        ],
        [
            "UR inverse kinematics",
            f"{k['ik_ur5e_poses_per_s_8_branches']:,} poses/s",
            "[sorting](docs/sorting.md)",
        ],
        [
            "sorting, random scenes (truth calibration)",
            f"{s['truth_sorted_ok']}/{s['truth_cubes']} in the right bin, {s['truth_collisions']} "
            f"collisions, cubes {s['truth_mean_position_error_mm']:.2f} mm",
            "[sorting](docs/sorting.md)",
        ],
        [
            "pick cycle at the shipped limits (120°/s, 300 mm/s): picks per minute, motion / "
            "planned lower bound, computation waited for, per pick",
            f"{s['truth_picks_per_minute']:.2f}/min, {s['truth_motion_s_per_pick']:.2f} / "
            f"{s['truth_lower_bound_s_per_pick']:.2f} s, {s['truth_wait_s_per_pick']:.3f} s",
            "[sorting](docs/sorting.md)",
        ],
        [
            f"`omnisort serve` soak, {r['soak']['soak_s'] / 60:.0f} min of jobs and abuse",
            f"{r['soak']['errors']} errors, RSS {r['soak']['rss_drift_pct']:+.1f} %, "
            f"descriptors {'–'.join(str(v) for v in r['soak']['fds_min_max'])}, largest `.rrd` "
            f"{r['soak']['rrd_largest_mb']:.1f} MB (limit {r['soak']['rrd_file_limit_mb']})",
            "[service](docs/service.md)",
        ],
        [
            "the real drivers on the virtual cell: `omnisort serve` sorts",
            f"{vc['sort_cubes_in_their_bin']}/{vc['sort_cubes']} in their bin, "
            f"{vc['sort_collisions']} collisions, {vc['sort_seconds_per_pick']:.1f} s per pick",
            "[virtual cell](docs/virtual_cell.md)",
        ],
    ]
    if "drift" in r:
        d = r["drift"]
        sizes = ("0.05", "0.1", "0.3", "1")
        rows.append(
            [
                "drift watchdog: camera unmoved / knocked 0.05–1° (X, Y, Z)",
                f"{d['false_alarms']} false alarms in {d['unmoved_captures']} captures / "
                f"{sum(d[f'bump_{s}_detected'] for s in sizes)}/"
                f"{sum(d[f'bump_{s}_captures'] for s in sizes)} detected, angle within "
                f"{max(d[f'bump_{s}_max_angle_error_deg'] for s in sizes)}°",
                "[drift](docs/drift.md)",
            ]
        )
    if "uncertainty" in r:
        rows += uncertainty_rows(r["uncertainty"])
    if "sweep" in r:
        sw = r["sweep"]
        rows.append(
            [
                f"sweeps on {sw['cores']} cores: speed-up of a {sw['workers']}-worker pool / "
                "Dask LocalCluster against serial (shared, loaded machine)",
                f"{sw['pool_speedup']:.2f}x / {sw['dask_speedup']:.2f}x, results identical: "
                f"{'yes' if sw['identical_results'] else 'NO'}",
                "[sweeps](docs/sweeps.md)",
            ]
        )
    return _table(["what", "measured", "more"], rows) + f"\nMachine: {_machine(r)}.\n"


def drift(r: dict[str, Any]) -> str:
    d = r["drift"]
    rows: list[list[Any]] = [
        [
            "camera unmoved (clean and degraded, arm in random poses)",
            d["unmoved_captures"],
            f"{d['false_alarms']} false alarms ({d['occluded_captures']} with board corners "
            f"unseen: arm or noise); largest angle {d['max_unmoved_angle_deg']}°",
            "",
        ]
    ]
    for size in ("0.05", "0.1", "0.3", "1"):
        rows.append(
            [
                f"bump {size}° (X, Y, Z of S, both signs)",
                d[f"bump_{size}_captures"],
                f"{d[f'bump_{size}_detected']} detected",
                f"{d[f'bump_{size}_max_angle_error_deg']}°",
            ]
        )
    return (
        _table(["case", "captures", "outcome", "implied angle error, max"], rows)
        + f"\nThreshold = the larger of the noise-derived one (least precise direction) and "
        f"`min_angle_deg` (0.02°): median {d['threshold_deg_median']}°, max "
        f"{d['threshold_deg_max']}° (0.02° means the noise-derived part was below it); "
        f"seed {d['seed']}, "
        f"{d['width_px']} px, {d['scenes']} scenes; {d['seconds_per_check_with_render']} s per "
        f"capture and check. PLC: one read of the 11 input registers {d['plc_read_ms_median']} ms "
        f"median, {d['plc_read_ms_p99']} ms p99.\n"
    )


def lighting(r: dict[str, Any]) -> str:
    """Hostile light: single frame vs measurement capture, per scenario."""
    li = r["lighting"]
    rows: list[list[Any]] = []

    def num(v: Any, fmt: str) -> str:
        return format(v, fmt) if isinstance(v, (int, float)) else "–"

    for name, sc in li["scenarios"].items():
        for key, label in (("single", "single frame"), ("capture", "capture")):
            e = sc[key]
            if "error" in e:
                rows.append([name, label, "failed", "", "", ""])
                continue
            cal = (
                f"{num(e['calibration_max_error_deg'], '.4f')}° / "
                f"{num(e['calibration_distance_error_mm'], '.2f')} mm"
                if e.get("calibration_max_error_deg") is not None
                else "failed"
            )
            rows.append(
                [
                    name,
                    label,
                    f"{e['spurious_points']} of {e['laser_points']}",
                    f"{num(e['mapping_max_rel_error_pct'], '.3f')} %",
                    cal,
                    f"{num(e['capture_s'], '.3f')} s",
                ]
            )
    head = ["scenario", "method", "spurious points", "map distance error", "calibration error"]
    note = (
        f"\nSorting cell, {li['width']} px, seed {li['seed']}, capture of {li['frames']} "
        "on/off pairs; calibration error: worst angle / laser distance (joint); capture "
        "time: exposures plus laser switching.\n"
    )
    for seed, chk in li.get("check_seeds", {}).items():
        cap, one = chk["capture"], chk["single"]
        note += (
            f"Seed {seed} (nothing tuned on it), all five scenarios: capture "
            f"{cap['spurious_points']} spurious of {cap['laser_points']} points, worst map "
            f"error {num(cap['mapping_max_rel_error_pct'], '.3f')} %; single frame "
            f"{one['spurious_points']} of {one['laser_points']}, "
            f"{num(one['mapping_max_rel_error_pct'], '.3f')} %.\n"
        )
    small = li.get("small_width", {})
    if small.get("seeds"):
        worst = [s["capture"]["mapping_max_rel_error_pct"] for s in small["seeds"].values()]
        spurious = sum(s["capture"]["spurious_points"] for s in small["seeds"].values())
        note = note.rstrip("\n") + (
            f" At {small['width']} px (the CLI's default), seeds "
            f"{', '.join(small['seeds'])}: capture {spurious} spurious points, worst map "
            f"error {num(max(w for w in worst if w is not None), '.3f')} %.\n"
        )
    return _table([*head, "capture time"], rows) + note


def table3_capture(r: dict[str, Any]) -> str:
    """Table 3 with captures against clean renders at the same size."""
    t = r["table3_capture"]
    rows: list[list[Any]] = []
    for key, label in (("joint", "joint"), ("paper", "paper"), ("method1", "method 1")):
        if f"capture_{key}_mae" not in t:
            continue
        cap, clean, ratio = (
            t[f"capture_{key}_mae"],
            t[f"clean_{key}_mae"],
            t[f"{key}_ratio_to_clean"],
        )
        rows.append([f"{label}, capture"] + [f"{cap[p]:.4f}" for p in PARAMS])
        rows.append([f"{label}, clean"] + [f"{clean[p]:.4f}" for p in PARAMS])
        rows.append([f"{label}, ratio"] + [f"{ratio[p]:.2f}x" for p in PARAMS])
    unseen = t.get("unseen_seeds", {})
    for seed, u in unseen.items():
        if not isinstance(u, dict) or "joint_mae" not in u:
            continue
        verdict = "met" if u["joint_goal_met"] else "NOT met"
        rows.append(
            [f"joint, capture, seed {seed} (unseen; goal {verdict})"]
            + [f"{u['joint_mae'][p]:.4f}" for p in PARAMS]
        )
    run = (
        f"; the whole run took {t['run_wall_s'] / 60:.0f} min on the shared 2-core machine"
        if t.get("run_wall_s")
        else ""
    )
    note = (
        f"\n{t.get('configurations_done', t['configurations'])} of {t['configurations']} "
        f"configurations (clean: the renders the captures are exposed from), seed {t['seed']}, "
        f"{t['width']} px, captures of {t['frames']} on/off pairs (mean capture time "
        f"{t['mean_capture_s']:.3f} s, {t['re_exposures']} re-exposures); mapping check max "
        f"error {t['mapping_max_rel_error_pct']:.3f} % "
        f"(clean {t['clean_mapping_max_rel_error_pct']:.3f} %){run}.\n"
    )
    if unseen:
        note += (
            f"Goal (absolute; the ratio to clean is no longer one): `joint` MAE at most "
            f"{unseen['goal_deg']}° per angle and {unseen['goal_mm']} mm, on seeds nothing was "
            f"tuned on ({unseen['configurations']} configurations each); seed "
            f"{t['seed']}, the development seed: "
            f"{'met' if t.get('joint_goal_met_seed0') else 'NOT met'}.\n"
        )
    return _table(["MAE", *PARAM_HEADS.split(" | ")], rows) + note


def sweeps(r: dict[str, Any]) -> str:
    """A small sweep serial, on the pool and on a local Dask cluster: wall time, speed-up,
    time per trial, and the machine's load around each run."""
    s = r["sweep"]
    rows: list[list[Any]] = []
    for name, label in (
        ("serial", "serial (this process)"),
        ("pool", f"local pool, {s['workers']} workers"),
        ("dask", f"Dask LocalCluster, {s['workers']} workers"),
    ):
        speedup = "1" if name == "serial" else f"{s[f'{name}_speedup']:.2f}"
        rows.append(
            [
                label,
                f"{s[f'{name}_s']:.1f} s ({s[f'{name}_start_s']:.1f} s to start)",
                f"{speedup}x",
                f"{s[f'{name}_trial_s_mean']:.1f} s / {s[f'{name}_trial_cpu_s_mean']:.1f} s",
                f"{s[f'{name}_load_before']:.1f} → {s[f'{name}_load_after']:.1f}",
            ]
        )
    head = ["executor", "sweep", "speed-up", "per trial, wall / CPU", "load average (1 min)"]
    same = "identical" if s["identical_results"] else "DIFFERENT"
    return _table(head, rows) + (
        f"\n{s['trials']} {s['experiment']} trials ({s['width_px']} px, seed {s['seed']}) on "
        f"{s['cores']} cores ({s['cpu']}); result rows {same} on the three executors. A "
        f"trial costs a single-thread worker about {s['pool_trial_cpu_s_mean']:.1f} s of CPU "
        "at this size (the pool's): N trials on W such workers take about N x that / W, plus "
        "the workers' start.\n"
    )


GENERATORS: dict[str, Callable[[dict[str, Any]], str]] = {
    "summary": summary,
    "table3": table3,
    "reference": reference,
    "reference_errors": reference_errors,
    "reference_features": reference_features,
    "intrinsics": intrinsics,
    "extrinsics_speed": extrinsics_speed,
    "kinematics": kinematics,
    "sorting": sorting,
    "service": service,
    "virtual_cell": virtual_cell,
    "soak": soak,
    "stream_stripe": stream_stripe,
    "drift": drift,
    "lighting": lighting,
    "table3_capture": table3_capture,
    "sweeps": sweeps,
    "uncertainty": uncertainty,
    "real_light": real_light,
    "real_light_camera": real_light_camera,
    "table3_effects": table3_effects,
    "table3_effects_captures": table3_effects_captures,
    "stripe_effects": stripe_effects,
}


def render(text: str, results: dict[str, Any]) -> str:
    """`text` with every figures block and inline figure regenerated (KeyError names an
    unknown block or a path results.json lacks)."""

    def one(m: re.Match[str]) -> str:
        return m.group(1) + GENERATORS[m.group(2)](results) + m.group(4)

    return prose.render_inline(BLOCK.sub(one, text), results)


def blocks(text: str) -> list[str]:
    return [m.group(2) for m in BLOCK.finditer(text)]


def load_results() -> dict[str, Any]:
    return json.loads((HERE / "results.json").read_text(encoding="utf-8"))


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.figures")
    parser.add_argument("--write", action="store_true", help="rewrite the blocks in place")
    args = parser.parse_args()
    results = load_results()
    stale = []
    for path in DOCUMENTS:
        text = path.read_text(encoding="utf-8")
        new = render(text, results)
        if new != text:
            stale.append(path)
            if args.write:
                path.write_text(new, encoding="utf-8")
    for path in stale:
        print(f"{path.relative_to(ROOT)}: {'rewritten' if args.write else 'stale'}")
    bare, unused = prose.check(list(DOCUMENTS), ROOT, prose.load_allowlist(ALLOWLIST))
    for hit in bare:
        print(f"{hit}\n    measured, not generated: use <!-- fig:PATH|FMT --> or {ALLOWLIST.name}")
    for entry in unused:
        print(f"{ALLOWLIST.name}: excuses nothing now: {entry.path} | {entry.text}")
    return 1 if (stale and not args.write) or bare or unused else 0


if __name__ == "__main__":
    sys.exit(main())
