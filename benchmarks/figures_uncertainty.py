"""The README's uncertainty table, from results.json's `uncertainty` section."""

from __future__ import annotations

from typing import Any

TARGET = "std 0.8-1.25, 90-98 % within the 95 % interval"


def _z(f: dict[str, Any]) -> str:
    if not f.get("n"):
        return "no points"
    return (
        f"{f['n']} over {len(f['seeds'])} seeds: z std {f['z_std']:.2f} (mean {f['z_mean']:+.2f}),"
        f" {100 * f['within_95_fraction']:.1f} % within; sigma {f['sigma_median_mm']:.3f} mm"
        f" (median), error {f['error_rms_mm']:.3f} mm RMS"
    )


def _verdict(f: dict[str, Any]) -> str:
    if not f.get("n"):
        return "-"
    ok = 0.8 <= f["z_std"] <= 1.25 and 0.90 <= f["within_95_fraction"] <= 0.98
    return "met" if ok else "**not met**"


def uncertainty(r: dict[str, Any]) -> str:
    u = r["uncertainty"]
    rows = [
        (
            "map points on the walls (obstacle faces)",
            _z(u["map"]["walls"]),
            _verdict(u["map"]["walls"]),
        ),
        (
            "map points on the floor (laser at grazing incidence)",
            _z(u["map"]["floor"]),
            _verdict(u["map"]["floor"]),
        ),
        ("cube centres (x and y in B)", _z(u["cubes"]), _verdict(u["cubes"])),
    ]
    out = [
        "| predicted sigma against simulator truth | measured | target: " + TARGET + " |",
        "| --- | --- | --- |",
        *(f"| {a} | {b} | {c} |" for a, b, c in rows),
    ]
    f2 = u["fisheye2"]
    lines = ["", "| Fisheye2 (real lens) | this project | mrcal 2.2 |", "| --- | --- | --- |"]
    if "skipped" not in f2:
        at = f2["projection_px_at_deg"]
        m = f2["mrcal"]
        mid, rim = m["projection_px_45_70_deg"], m["projection_px_80_deg"]
        top = f2["projection_px_max_in_view"]
        lines += [
            f"| projection uncertainty on the axis | {at['0']:.3f} px"
            f" | {m['projection_px_centre']} px |",
            f"| ... at 45 / 60 / 70 deg | {at['45']:.3f} / {at['60']:.3f} / {at['70']:.3f} px"
            f" | {mid[0]}-{mid[1]} px |",
            f"| ... at 80 deg | {at['80']:.3f} px | {rim[0]}-{rim[1]} px |",
            f"| ... largest in the image (no board there) | {top:.2f} px | |",
            f"| {f2['cross_validation_scheme']}: held-out RMS / in sample | "
            f"{f2['cross_validation_rms_px']:.3f} / {f2['in_sample_rms_px']:.3f} px"
            f" | {m['leave_one_out_rms_px_opencv8']} px (OPENCV8, held out) |",
            f"| views | {f2['images_used']} of {f2['images_given']} used; repeated: "
            f"{', '.join(f2['repeated_views']) or 'none'} | |",
        ]
    g = u["gated_sort"]
    c = u["cost"]
    refused = [x for x in g["cubes"] if x["status"] == "skipped"]
    sorted_ = [x for x in g["cubes"] if x["status"] == "sorted" and x["in_right_bin"]]
    lines += [
        "",
        f"Gated sort (camera yaw uncertain by {g['yaw_sigma_deg']} deg, capture tolerance "
        f"{g['capture_tolerance_mm']:g} mm): {len(sorted_)} cubes sorted into their bins, "
        f"{g['collisions']} collisions; refused: "
        + "; ".join(f"{x['color']} ({x['reason']})" for x in refused)
        + ".",
        "",
        (
            f"Cost, 1920 px frame, one core: the sigmas of its {c['points']} points "
            f"{c['sigmas_only_ms_one_core']} ms; "
            if "points" in c
            else "Cost, 1920 px frame, one core: "
        )
        + f"map {c['map_1920_ms_one_core']} ms, with every "
        f"point's sigma {c['map_1920_with_sigmas_ms_one_core']} ms; the whole `map_laser` "
        f"(echoes, stripe ends) {c['map_laser_1920_ms_one_core']} / "
        f"{c['map_laser_1920_with_sigmas_ms_one_core']} ms,"
        f" with {c['intrinsic_modes']} intrinsic modes too "
        f"{c['map_laser_1920_with_sigmas_and_intrinsic_modes_ms_one_core']} ms "
        f"(load average {c['load_average_1min']}).",
        f"Seeds {u['seeds'][0]}-{u['seeds'][-1]} (`OMNISORT_UNCERTAINTY_SEEDS`; the model "
        "was built on 0-3, its cube part corrected on 100-105), "
        f"{u['width_px']} px.",
    ]
    return "\n".join(out + lines) + "\n"


def uncertainty_rows(u: dict[str, Any]) -> list[list[str]]:
    """The summary table's rows: the sigmas' calibration against truth, the real lens."""
    w, fl, c = u["map"]["walls"], u["map"]["floor"], u["cubes"]
    rows = [
        [
            "predicted sigma against truth, held-out seeds: map points on walls / on the floor / "
            "cube centres (target: z std 0.8-1.25, 90-98 % in the 95 % interval)",
            f"z std {w['z_std']:.2f}, {100 * w['within_95_fraction']:.1f} % ({w['n']} points) / "
            f"{fl['z_std']:.2f}, {100 * fl['within_95_fraction']:.1f} % ({fl['n']} points) / "
            f"{c['z_std']:.2f}, {100 * c['within_95_fraction']:.1f} % ({c['n']} coordinates)",
            "[uncertainty](docs/uncertainty.md)",
        ]
    ]
    f2 = u["fisheye2"]
    if "skipped" not in f2:
        at = f2["projection_px_at_deg"]
        rows.append(
            [
                "fisheye2 projection uncertainty at 0 / 45-70 / 80° (mrcal: 0.06 / 0.08-0.16 / "
                "0.25-0.88 px); held-out / in-sample RMS",
                f"{at['0']:.3f} / {at['45']:.3f}-{at['70']:.3f} / {at['80']:.3f} px; "
                f"{f2['cross_validation_rms_px']:.3f} / {f2['in_sample_rms_px']:.3f} px",
                "[uncertainty](docs/uncertainty.md)",
            ]
        )
    return rows
