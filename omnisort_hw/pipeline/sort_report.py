"""A sorting run's record: what happened to each located cube, and the run's totals, as the
service replies, the CLI prints and the evaluation counts them."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from omnisort_hw.pipeline.replies import CubeOutcome, SortExtras, SortReply, SortTotals
from omnisort_hw.pipeline.verdict import Verdict, none_of

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

    def totals(self) -> SortTotals:
        picked = [o for o in self.outcomes if o.status == "sorted"]
        per_pick = sum(o.planned_motion_s for o in picked) / len(picked) if picked else None
        errs = [o.error_mm for o in self.outcomes if o.error_mm is not None]
        return SortTotals(
            cubes=len(self.outcomes),
            sorted=len(picked),
            skipped=sum(o.status == "skipped" for o in self.outcomes),
            failed=sum(o.status == "failed" for o in self.outcomes),
            planned_motion_s=round(sum(o.planned_motion_s for o in self.outcomes), 3),
            planned_motion_s_per_pick=round(per_pick, 3) if per_pick is not None else None,
            wall_s=round(self.wall_s, 3),
            sorted_ok=sum(bool(o.in_right_bin) for o in self.outcomes) if self.verified else None,
            mean_position_error_mm=round(float(np.mean(errs)), 3)
            if self.verified and errs
            else None,
            collisions=self.collisions if self.verified else None,
        )

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
        """The answer at every door (the service's reply, the CLI's `--json`): each cube's
        outcome rounded (mm to 0.01, sigmas and times to 0.001)."""
        return SortReply(
            cubes=[_rounded(o) for o in self.outcomes],
            totals=self.totals(),
            registration=self.registration,
            rejected_blobs=self.rejected_blobs,
            verdict=self.verdict(),
            **vars(self.extra),
        )


def _rounded(o: CubeOutcome) -> CubeOutcome:
    return replace(
        o,
        center_S_mm=[round(v, 2) for v in o.center_S_mm],
        center_B_mm=[round(v, 2) for v in o.center_B_mm],
        yaw_B_deg=round(o.yaw_B_deg, 2),
        sigma_mm=round(o.sigma_mm, 3),
        planned_motion_s=round(o.planned_motion_s, 3),
        error_mm=round(o.error_mm, 3) if o.error_mm is not None else None,
    )
