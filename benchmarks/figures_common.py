"""What the figures' generators share: the Table 3 parameters and a Markdown table."""

from __future__ import annotations

from typing import Any

ANGLES = ("cam_roll_deg", "cam_pitch_deg", "cam_yaw_deg", "laser_roll_deg", "laser_pitch_deg")
PARAMS = (*ANGLES, "laser_distance_mm")
PARAM_HEADS = "cam roll ° | cam pitch ° | cam yaw ° | laser roll ° | laser pitch ° | laser d mm"


def table(head: list[str], rows: list[list[Any]]) -> str:
    """A Markdown table of `rows` under `head`."""
    lines = ["| " + " | ".join(head) + " |", "| " + " | ".join("---" for _ in head) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"
