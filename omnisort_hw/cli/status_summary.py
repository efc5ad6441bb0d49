"""The one-screen reading of a `status` reply (`omnisort ctl status`); `--json` gives the
whole record. Every part is optional: a field the service does not send is left out."""

from __future__ import annotations

from typing import Any


def _device(name: str, dev: dict[str, Any]) -> str:
    if not dev.get("configured", True):
        return f"{name:<7}not configured"
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
    return f"{name:<7}" + ", ".join(parts)


def _calibration(cal: dict[str, Any]) -> list[str]:
    lines = []
    for kind, f in (cal.get("files") or {}).items():
        age = f.get("age_days")
        when = f" ({age:.1f} days old)" if isinstance(age, int | float) else ""
        text = f"{kind}.json {f.get('health', '?')}{when}"
        if f.get("health") != "ok" and f.get("message"):
            text += f": {f['message']}"
        lines.append(text)
    lines.append("robot registered" if cal.get("robot_registered") else "robot NOT registered")
    return lines


def _job(job: dict[str, Any] | None) -> str:
    if not job:
        return "none"
    text = f"{job.get('cmd')} (request {job.get('request_id')}), {job.get('running_s', 0):.1f} s"
    progress = job.get("progress") or []
    if progress:
        last = progress[-1]
        text += "; last: " + ", ".join(f"{k} {v}" for k, v in last.items())
    return text


def summarise(status: dict[str, Any]) -> str:
    """About fifteen lines: state, job, whether motion is allowed and why not, devices,
    calibration files, drift, gripper, logging and the service itself."""
    rows: list[tuple[str, str]] = []
    reason = f" ({status['reason']})" if status.get("reason") else ""
    rows.append(("state", f"{status.get('state', '?')}{reason}"))
    rows.append(("job", _job(status.get("job"))))
    cal = status.get("calibration") or {}
    drift = status.get("drift") or {}
    if status.get("motion_allowed") and not drift.get("motion_refused"):
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
        rows.append(("devices" if i == 0 else "", _device(name, dev)))
    for i, line in enumerate(_calibration(cal) if cal else []):
        rows.append(("calibration" if i == 0 else "", line))
    if drift:
        last = drift.get("last")
        if not last:
            seen = "never checked"
        elif isinstance(last, dict):
            seen = ", ".join(f"{k} {v}" for k, v in last.items() if not isinstance(v, dict))
        else:
            seen = str(last)
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
    width = max(len(k) for k, _ in rows) + 2
    return "\n".join(f"{k:<{width}}{v}" for k, v in rows)
