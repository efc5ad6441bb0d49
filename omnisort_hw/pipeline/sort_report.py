"""A sorting run's record: what happened to each located cube, and the run's totals, as the
service replies, the CLI prints and the evaluation counts them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from omnisort_hw.pipeline.replies import SortExtras, SortReply
from omnisort_hw.pipeline.verdict import Verdict, none_of, to_wire_verdict


def _finite(value: float, digits: int) -> float | None:
    """A rounded number for JSON, None when it is not finite (strict JSON has no NaN)."""
    return round(float(value), digits) if math.isfinite(value) else None


@dataclass
class CubeOutcome:
    """What happened to one located cube."""

    index: int
    color: str
    center_S_mm: list[float]
    center_B_mm: list[float]
    yaw_B_deg: float
    sigma_mm: float
    status: str  # "sorted" (placed), "skipped" (refused before motion), "failed"
    reason: str = ""
    bin: str | None = None
    planned_motion_s: float = 0.0  # the pick's planned motion (its lower bound)
    error_mm: float | None = None  # filled by a verifier
    in_right_bin: bool | None = None  # filled by a verifier
    relocated: bool = False  # moved after the first capture; located again by a check

    def to_dict(self) -> dict[str, Any]:
        out = {
            "index": self.index,
            "color": self.color,
            "center_S_mm": [_finite(v, 2) for v in self.center_S_mm],
            "center_B_mm": [_finite(v, 2) for v in self.center_B_mm],
            "yaw_B_deg": _finite(self.yaw_B_deg, 2),
            "sigma_mm": _finite(self.sigma_mm, 3),
            "status": self.status,
            "reason": self.reason,
            "bin": self.bin,
            "planned_motion_s": round(self.planned_motion_s, 3),
        }
        if self.error_mm is not None:
            out["error_mm"] = round(self.error_mm, 3)
        if self.in_right_bin is not None:
            out["in_right_bin"] = self.in_right_bin
        if self.relocated:
            out["relocated"] = True
        return out


MAX_REACHED = "max_objects reached"
"""The reason of a cube left because the request asked for fewer."""


@dataclass
class SortReport:
    """Per-cube outcomes and totals of one sorting run."""

    outcomes: list[CubeOutcome]
    registration: dict[str, Any] | None = None
    rejected_blobs: int = 0
    wall_s: float = 0.0
    verified: bool = False
    collisions: int | None = None
    extra: SortExtras = field(default_factory=lambda: SortExtras())

    def add_missed(self, color: str, center_S_mm: list[float], in_right_bin: bool) -> None:
        """A cube a verifier knows of that the run never located (status "missed")."""
        self.outcomes.append(
            CubeOutcome(
                len(self.outcomes),
                color,
                list(center_S_mm),
                [float("nan")] * 3,
                0.0,
                float("nan"),
                "missed",
                "not located",
                None,
                in_right_bin=in_right_bin,
            )
        )

    def totals(self) -> dict[str, Any]:
        picked = [o for o in self.outcomes if o.status == "sorted"]
        out: dict[str, Any] = {
            "cubes": len(self.outcomes),
            "sorted": len(picked),
            "skipped": sum(o.status == "skipped" for o in self.outcomes),
            "failed": sum(o.status == "failed" for o in self.outcomes),
            "planned_motion_s": round(sum(o.planned_motion_s for o in self.outcomes), 3),
            "planned_motion_s_per_pick": round(
                sum(o.planned_motion_s for o in picked) / len(picked), 3
            )
            if picked
            else None,
            "wall_s": round(self.wall_s, 3),
        }
        if self.verified:
            out["sorted_ok"] = sum(bool(o.in_right_bin) for o in self.outcomes)
            errs = [o.error_mm for o in self.outcomes if o.error_mm is not None]
            out["mean_position_error_mm"] = round(float(np.mean(errs)), 3) if errs else None
            out["collisions"] = self.collisions
        return out

    def verdict(self) -> Verdict:
        """Every located cube sorted passes; a skipped one (too uncertain, no bin, cancelled)
        is a warning with its reason; a failed pick fails; with a verifier, a cube out of its
        bin fails too. A cube left because the request's `max_objects` was reached was not
        asked for: neither a warning nor out of its bin."""
        asked = [
            o for o in self.outcomes if not (o.status == "skipped" and o.reason == MAX_REACHED)
        ]
        reasons = sorted({o.reason for o in asked if o.status != "sorted" and o.reason})
        advice = "; ".join(reasons[:3])
        checks = [
            none_of("failed picks", sum(o.status == "failed" for o in asked), "fail", advice),
            none_of("skipped cubes", sum(o.status == "skipped" for o in asked), "warn", advice),
        ]
        if self.verified:
            out_of_bin = sum(not o.in_right_bin for o in asked)
            checks.append(none_of("cubes not in their bin", out_of_bin, "fail"))
        return Verdict("sort", tuple(checks))

    def reply(self) -> SortReply:
        """The answer at every door (the service's reply, the CLI's `--json`)."""
        return {
            "cubes": [o.to_dict() for o in self.outcomes],
            "totals": self.totals(),
            "registration": self.registration,
            "rejected_blobs": self.rejected_blobs,
            **self.extra,
            "verdict": to_wire_verdict(self.verdict()),
        }
