"""docs/real_light.md's tables, from results.json's `real_light` and `table3_effects`
sections: the stripe extractor on real photographs, the colour camera measured on them, and
Table 3 through the simulated colour camera."""

from __future__ import annotations

from typing import Any

from benchmarks.figures_common import PARAM_HEADS, PARAMS
from benchmarks.figures_common import table as _table


def real_light(r: dict[str, Any]) -> str:
    """The stripe extractor on real photographs: before the real-light rules and now."""
    rl = r["real_light"]

    def pct(v: Any) -> str:
        return f"{100 * v:.0f} %" if isinstance(v, (int, float)) else "–"

    def px(v: Any) -> str:
        return f"{v:.1f} px" if isinstance(v, (int, float)) else "–"

    rows: list[list[Any]] = []
    for when in ("before", "now"):
        for name, s in rl[when].items():
            if name.startswith("_"):
                continue
            if name.endswith("(laser off)"):
                rows.append(
                    [
                        when,
                        name,
                        s["photos"],
                        f"{s['with_phantoms']} with phantoms "
                        f"(at most {s['phantom_points_max']} points)",
                        "",
                        "",
                        "",
                    ]
                )
                continue
            rows.append(
                [
                    when,
                    name,
                    s["photos"],
                    pct(s["off_on_board_mean"]),
                    pct(s["coverage_mean"]),
                    px(s["clipped_median_px"]),
                    pct(s["clipped_split_mean"]),
                ]
            )
    renders = rl["now"].get("_laser_off_renders")
    if renders is not None:  # the simulator's cluttered cell, laser off, through the effects
        for when, key in (("without the line rule", "without_line_rule"), ("now", "now")):
            s = renders[key]
            rows.append(
                [
                    when,
                    f"sorting cell renders, {renders['width_px']} px, colour camera (laser off)",
                    s["renders"],
                    f"{s['with_phantoms']} with phantoms (at most {s['phantom_points_max']} "
                    "points)",
                    "",
                    "",
                    "",
                ]
            )
    head = [
        "extractor",
        "set",
        "photos",
        "off the stripe, on the board",
        "coverage",
        "clipped: from the run's centre",
        "clipped lines measured twice",
    ]
    note = (
        f"\nMeans over each set's photographs; the extractor took "
        f"{rl['now']['_extract_s_mean']:.3f} s per photograph on average "
        f"({rl.get('_machine', {}).get('cores', '?')} cores).\n"
    )
    return _table(head, rows) + note


def real_light_camera(r: dict[str, Any]) -> str:
    """The colour camera measured on the real photographs (`evaluation.camera_measures`)."""
    cam = r["real_light"]["now"]["_camera"]

    def p3(v: Any) -> str:
        return " / ".join(f"{x:.2f}" for x in v) if v else "–"

    rows: list[list[Any]] = []
    for name, m in cam.items():
        xt = m["crosstalk_p10_p50_p90"]
        ca = m["chromatic_px_at_corner_p10_p50_p90"]
        halo = m["halo_share_median"]
        rows.append(
            [
                name,
                f"{m['crosstalk_photos']}: "
                + "; ".join(f"{k} {p3(v)}" for k, v in xt.items() if v is not None),
                f"{m['chromatic_photos']}: red {p3(ca['red'])}; blue {p3(ca['blue'])}",
                f"{m['halo_photos']}: " + (" / ".join(f"{x:.2f}" for x in halo) if halo else "–"),
            ]
        )
    head = [
        "set",
        "crosstalk (photos: channel p10 / p50 / p90)",
        "chromatic shift at the corner, px (photos: p10 / p50 / p90)",
        "halo beside a clipped core, share of the clip at "
        + ", ".join(str(d) for d in cam[next(iter(cam))]["halo_at_px"])
        + " px (photos: medians)",
    ]
    return _table(head, rows)


def table3_effects(r: dict[str, Any]) -> str:
    """Each method's Table 3 MAE through the colour camera against clean, per unseen seed."""
    t = r["table3_effects"]
    rows: list[list[Any]] = []
    for seed in t["seeds"]:
        e = t[str(seed)]
        for key, label in (("joint", "joint"), ("paper", "paper"), ("method1", "method 1")):
            if f"{key}_effects_mae" not in e:
                continue
            fx, clean, ratio = e[f"{key}_effects_mae"], e[f"{key}_clean_mae"], e[f"{key}_ratio"]
            rows.append([f"seed {seed}, {label}, colour camera"] + [f"{fx[p]:.4f}" for p in PARAMS])
            rows.append([f"seed {seed}, {label}, clean"] + [f"{clean[p]:.4f}" for p in PARAMS])
            rows.append(
                [f"seed {seed}, {label}, ratio"]
                + [f"{ratio[p]:.2f}x" if ratio[p] is not None else "–" for p in PARAMS]
            )
    ablation = t.get("ablation", {})
    for name, a in ablation.items():
        if not isinstance(a, dict):
            continue
        seed, ratio = ablation["seed"], a["joint_ratio"]
        rows.append(
            [f"seed {seed}, joint, {name} ({a['joint_failures']} failed)"]
            + [f"{a['joint_mae'][p]:.4f}" for p in PARAMS]
        )
        rows.append(
            [f"seed {seed}, joint, {name}: ratio"]
            + [f"{ratio[p]:.2f}x" if ratio[p] is not None else "–" for p in PARAMS]
        )
    sensor = ablation.get("sensor only")
    if isinstance(sensor, dict) and str(ablation.get("seed")) in t:
        seed = ablation["seed"]
        fx = t[str(seed)]["joint_effects_mae"]
        rows.append(
            [f"seed {seed}, joint, colour camera over sensor only"]
            + [f"{fx[p] / sensor['joint_mae'][p]:.2f}x" for p in PARAMS]
        )
    verdicts = ", ".join(
        f"seed {s}: {'met' if t[str(s)]['joint_within_goal'] else 'NOT met'}, "
        f"{t[str(s)].get('joint_effects_failures', '?')} failed" + " of " + str(t["configurations"])
        for s in t["seeds"]
    )
    note = (
        f"\n{t['configurations']} configurations per seed, seeds nothing was tuned on; goal: "
        f"`joint` within {t['goal_ratio']:g}x of its clean MAE on every parameter ({verdicts}).\n"
    )
    return _table(["MAE", *PARAM_HEADS.split(" | ")], rows) + note


def table3_effects_captures(r: dict[str, Any]) -> str:
    """Table 3 on captures through the colour camera: each method's MAE per unseen seed, its
    ratio to the clean renders and to the same captures without the effects."""
    c = r["table3_effects"]["captures"]
    seeds = sorted(k for k in c if k.isdigit())
    rows: list[list[Any]] = []
    for seed in seeds:
        e = c[seed]
        for key, label in (("joint", "joint"), ("paper", "paper"), ("method1", "method 1")):
            if f"{key}_mae" not in e:
                continue
            mae = e[f"{key}_mae"]
            rows.append(
                [f"seed {seed}, {label}, captures, colour camera"]
                + [f"{mae[p]:.4f}" for p in PARAMS]
            )
            for what, name in (("clean", "to clean"), ("captures", "to captures without effects")):
                ratio = e.get(f"{key}_ratio_to_{what}")
                if ratio is not None:
                    rows.append(
                        [f"seed {seed}, {label}, ratio {name}"]
                        + [f"{ratio[p]:.2f}x" if ratio[p] is not None else "–" for p in PARAMS]
                    )
    verdicts = ", ".join(
        f"seed {s}: {'met' if c[s]['joint_within_goal_of_captures'] else 'NOT met'}, "
        f"{c[s].get('joint_failures', '?')} failed of {c['configurations']}"
        for s in seeds
    )
    note = (
        f"\n{c['configurations']} configurations per seed, {c['frames']} laser-on and laser-off "
        f"frames each at {c['width']} px; goal: `joint` within "
        f"{r['table3_effects']['goal_ratio']:g}x of the same captures without the effects on "
        f"every parameter ({verdicts}).\n"
    )
    return _table(["MAE", *PARAM_HEADS.split(" | ")], rows) + note


def stripe_effects(r: dict[str, Any]) -> str:
    """The stripe's centre under each colour-camera effect against its true centre line."""
    s = r["stripe_effects"]
    rows: list[list[Any]] = []
    for name, entry in s.items():
        if not isinstance(entry, dict) or name.startswith("_"):
            continue
        for width, e in entry.items():
            rows.append(
                [
                    name,
                    width.removeprefix("sigma_") + " px",
                    f"{e['rows_rms_px']:.3f}",
                    f"{e['rows_worst_bias_px']:.3f}",
                    f"{e['tilted_rms_px']:.3f}",
                    f"{e['tilted_bias_px']:+.3f}",
                ]
            )
    head = [
        "effect",
        "line sigma",
        "along rows: RMS px",
        "along rows: worst bias px",
        "tilted: RMS px",
        "tilted: bias px",
    ]
    note = (
        f"\n{s['offsets']} sub-pixel offsets along the rows, one tilted line, "
        f"{s['size_px']} px frames; the extractor's goal: {s['goal_rms_px']:g} px RMS.\n"
    )
    return _table(head, rows) + note
