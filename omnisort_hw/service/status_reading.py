"""Readings of a `status` reply for people: the one-screen summary (`omnisort ctl status`;
`--json` gives the whole record) and what the operator interface shows (its rows, the per-pick
log, picks per minute, the drift alarm). Every part is optional: a field the service does not
send is left out. Pure functions of the reply, so each door reads it the same way."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any


def device_text(dev: dict[str, Any]) -> str:
    """One device's health and last reading, in a line."""
    if not dev.get("configured", True):
        return "not configured"
    parts = [str(dev.get("name", "?")), "connected" if dev.get("connected") else "NOT CONNECTED"]
    if dev.get("serial"):
        parts.append(f"serial {dev['serial']}")
    if dev.get("resolution"):
        parts.append("x".join(str(n) for n in dev["resolution"]))
    if "on" in dev:
        parts.append("on" if dev["on"] else "off")
    safety = dev.get("safety")
    if isinstance(safety, dict):
        ok = safety.get("ok")
        modes = f"{safety.get('robot_mode', '?')}/{safety.get('safety_mode', '?')}"
        parts.append(modes if ok else f"SAFETY {modes}")
    if dev.get("error"):
        parts.append(f"error: {dev['error']}")
    return ", ".join(parts)


def _calibration(cal: dict[str, Any]) -> list[str]:
    lines = []
    for kind, f in (cal.get("files") or {}).items():
        age = f.get("age_days")
        checksum = str(f.get("checksum") or "")
        short = f", {checksum[:15]}" if checksum else ""
        when = f" ({age:.1f} days old{short})" if isinstance(age, int | float) else ""
        text = f"{kind}.json {f.get('health', '?')}{when}"
        if f.get("health") != "ok" and f.get("message"):
            text += f": {f['message']}"
        lines.append(text)
    lines.append("robot registered" if cal.get("robot_registered") else "robot NOT registered")
    return lines


def drift_text(last: dict[str, Any]) -> str:
    """The last drift check in a line: its decision, the angle against its threshold, when."""
    angle, threshold = last.get("angle_deg"), last.get("threshold_deg")
    if not isinstance(angle, int | float):
        return ", ".join(f"{k} {v}" for k, v in last.items() if not isinstance(v, dict))
    text = f"{'DRIFT' if last.get('drift') else 'no drift'}: turned {angle:.3f} deg"
    if isinstance(threshold, int | float):
        text += f" (threshold {threshold:.3f} deg)"
    if last.get("source"):
        text += f", by the {last['source']}"
    if last.get("checked_at"):
        text += f", {last['checked_at']}"
    return text


def job_text(job: Mapping[str, Any] | None, last_event: bool = True) -> str:
    """The running job in a line: command, request, running time against what the last such
    job took on this cell, and (`last_event`) its last progress event."""
    if not job:
        return "none"
    text = f"{job.get('cmd')} (request {job.get('request_id')}), {job.get('running_s', 0):.0f} s"
    expected = job.get("expected_s")
    if isinstance(expected, int | float):
        text += f" of about {expected:.0f} s (its last run here)"
    progress = job.get("progress") or []
    if last_event and progress:
        text += "; last: " + ", ".join(f"{k} {v}" for k, v in progress[-1].items())
    return text


def summarise(status: dict[str, Any]) -> str:
    """About fifteen lines: state, job, whether motion is allowed and why not, devices,
    calibration files, drift, gripper, logging and the service itself."""
    rows = status_rows(status)
    width = max(len(k) for k, _ in rows) + 2
    return "\n".join(f"{k:<{width}}{v}" for k, v in rows)


def motion_offered(status: Mapping[str, Any]) -> bool:
    """The service would move the arm now: its calibration usable, not in fault, and no drift
    refusing motion."""
    drift = status.get("drift") or {}
    return bool(status.get("motion_allowed")) and not drift.get("motion_refused")


def status_rows(status: dict[str, Any]) -> list[tuple[str, str]]:
    """`summarise`'s rows: (heading, text), the heading empty on a continuation row."""
    rows: list[tuple[str, str]] = []
    reason = f" ({status['reason']})" if status.get("reason") else ""
    rows.append(("state", f"{status.get('state', '?')}{reason}"))
    rows.append(("job", job_text(status.get("job"))))
    cal = status.get("calibration") or {}
    drift = status.get("drift") or {}
    if motion_offered(status):
        rows.append(("motion", "allowed"))
    else:
        why = [
            f"{k}.json {f.get('health')}"
            for k, f in (cal.get("files") or {}).items()
            if f.get("health") != "ok"
        ]
        if status.get("state") == "fault":
            why.append("fault state")
        if drift.get("motion_refused"):
            why.append(f"drift: {drift.get('reason')}")
        rows.append(("motion", "REFUSED" + (f": {'; '.join(why)}" if why else "")))
    for i, (name, dev) in enumerate((status.get("devices") or {}).items()):
        rows.append(("devices" if i == 0 else "", f"{name:<7}{device_text(dev)}"))
    for i, line in enumerate(_calibration(cal) if cal else []):
        rows.append(("calibration" if i == 0 else "", line))
    if drift:
        last = drift.get("last")
        seen = drift_text(last) if isinstance(last, dict) else str(last or "never checked")
        rows.append(("drift", seen))
    gripper = status.get("gripper")
    if isinstance(gripper, dict):
        rows.append(("gripper", str(gripper.get("load", "?"))))
    logging = status.get("logging")
    if isinstance(logging, dict):
        state = "ok" if logging.get("ok") else f"PROBLEM: {logging.get('problem')}"
        rows.append(("logging", f"{state}, {logging.get('rrd')}"))
    svc = status.get("service") or {}
    if svc:
        rows.append(
            (
                "service",
                f"{svc.get('host')}:{svc.get('port')}, pid {svc.get('pid')}, up "
                f"{svc.get('uptime_s', 0):.0f} s, {svc.get('clients', 0)} client(s), "
                f"{svc.get('requests', 0)} request(s), {svc.get('errors', 0)} error(s)",
            )
        )
        errors = errors_text(svc)
        if errors:
            rows.append(("", errors))
    return rows


def errors_text(svc: Mapping[str, Any]) -> str:
    """The service's errors by code, most first, and the last one with its age: what a
    rising error count is made of ('' when there were none)."""
    by_code = svc.get("errors_by_code") or {}
    if not by_code:
        return ""
    counts = ", ".join(f"{code} {n}" for code, n in sorted(by_code.items(), key=lambda kv: -kv[1]))
    last = svc.get("last_error")
    if not isinstance(last, Mapping):
        return f"errors: {counts}"
    return (
        f"errors: {counts}; last, {last.get('age_s', 0):.0f} s ago: {last.get('code')}: "
        + str(last.get("message", ""))[:160]
    )


@dataclass(frozen=True)
class PickRow:
    """One line of a sort's per-pick log."""

    cube: int
    color: str
    bin: str | None
    outcome: str  # sorted, failed, skipped
    reason: str
    at: str  # when the service recorded it (ISO 8601), "" when it did not say


def pick_log(status: dict[str, Any]) -> list[PickRow]:
    """The current or last sort's picks, in order, from the journal's progress events."""
    run = status.get("last_run") or {}
    if run.get("job") != "sort":
        return []
    return [
        PickRow(
            int(ev["cube"]),
            str(ev.get("color", "?")),
            ev.get("bin"),
            str(ev.get("status", "?")),
            str(ev.get("reason") or ""),
            str(ev.get("at") or ""),
        )
        for ev in run.get("progress") or []
        if isinstance(ev, dict) and isinstance(ev.get("cube"), int)
    ]


@dataclass
class PickHistory:
    """The picks of every sort one page has seen, numbered across them: after a stop and a
    resume the first sort's picks stay, and each row says which sort (1, 2, ...) it was,
    counting the sorts that picked; a sort's own cube numbers start again at 0, as its location
    numbered them. The last `keep` sorts are kept."""

    keep: int = 20
    runs: dict[str, list[PickRow]] = field(default_factory=dict)  # by start time, in order

    def update(self, status: dict[str, Any]) -> list[tuple[int, int, PickRow]]:
        """(pick number from 1, sort number from 1, the pick) of every sort seen so far, the
        current or last one's as `status` has it now."""
        run = status.get("last_run") or {}
        if run.get("job") == "sort" and run.get("started"):
            self.runs[str(run["started"])] = pick_log(status)
            while len(self.runs) > self.keep:
                del self.runs[next(iter(self.runs))]
        picked = (picks for picks in self.runs.values() if picks)  # a refused sort: none
        rows = [(k, row) for k, picks in enumerate(picked, 1) for row in picks]
        return [(n, k, row) for n, (k, row) in enumerate(rows, 1)]


def _when(text: Any) -> datetime | None:
    try:
        return datetime.fromisoformat(str(text))
    except ValueError:
        return None


def picks_per_minute(status: dict[str, Any], now: datetime) -> float | None:
    """Cubes sorted per minute by the current or last sort, from its start to its end (or
    `now`, an aware datetime, while it runs); None before any time has passed."""
    run = status.get("last_run") or {}
    started = _when(run.get("started"))
    if run.get("job") != "sort" or started is None:
        return None
    end = _when(run.get("ended")) or now
    minutes = (end - started).total_seconds() / 60.0
    if minutes <= 0:
        return None
    return sum(p.outcome == "sorted" for p in pick_log(status)) / minutes


def sort_progress(status: dict[str, Any]) -> tuple[int, int] | None:
    """(cubes finished, cubes to pick) of the current or last sort; None before it planned."""
    run = status.get("last_run") or {}
    if run.get("job") != "sort":
        return None
    total = None
    for ev in run.get("progress") or []:
        if isinstance(ev, dict) and "to_pick" in ev:
            total = int(ev["to_pick"])
    if total is None:
        return None
    return len(pick_log(status)), total


def drift_alarm(status: dict[str, Any]) -> str | None:
    """The drift that refuses motion, with the angle the last check measured; None if none."""
    drift = status.get("drift") or {}
    if not drift.get("motion_refused"):
        return None
    last = drift.get("last")
    angle = last.get("angle_deg") if isinstance(last, dict) else None
    measured = f"camera turned {angle:.3f} deg" if isinstance(angle, int | float) else "drift"
    return f"{measured}: {drift.get('reason') or 'motion refused'}"
