"""Each protocol command as a function of the cell: `handler(ctx, args) -> result dict`.

Handlers run in worker threads (never in the event loop) and may block on devices; the
server bounds them with timeouts. Commands that act on the service itself (stop, estop,
reset, shutdown) live in the server, which owns the state machine.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from omnisort_hw.cell.cell import Cell
from omnisort_hw.pipeline.adopt import AdoptRequest
from omnisort_hw.pipeline.requests import (
    ExtrinsicsRequest,
    IntrinsicsRequest,
    LocateRequest,
    MapRequest,
    RegisterRequest,
    SortRequest,
)


@dataclass
class Context:
    """What a handler gets besides its arguments."""

    cell: Cell
    cancel: threading.Event
    service_status: Callable[[], dict[str, Any]]
    progress: Callable[[dict[str, Any]], None] | None = None


Handler = Callable[[Context, dict[str, Any]], dict[str, Any]]


def status(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    """Service state, job, devices and calibration health."""
    result = ctx.service_status()
    result.update(ctx.cell.status())
    cal = result["calibration"]
    result["motion_allowed"] = bool(cal["motion_allowed"]) and result["state"] != "fault"
    return result


def capture(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.capture(args["encoding"], args["format"], args["laser"])


def laser(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.laser(args["on"])


def calibrate(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    if args["what"] == "intrinsics":
        from omnisort_hw.pipeline.intrinsics import image_files

        folder = args["folder"]
        request = IntrinsicsRequest(
            tuple(image_files(folder)),
            args["square_mm"],
            board=args["board"],
            degree=args["degree"],
            folder=str(folder),
        )
        return ctx.cell.calibrate_intrinsics(request, ctx.cancel)
    return ctx.cell.calibrate_extrinsics(
        ExtrinsicsRequest(
            image=args["image"],
            target=args["target"],
            method=args["method"],
            separation_mm=args["separation_mm"],
            board=args["board"],
            square_mm=args["square_mm"],
        ),
        ctx.cancel,
    )


def map_scene(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    request = MapRequest(args["image"], with_points=args["points"], picture=args["picture"])
    return ctx.cell.map_scene(request, ctx.cancel)


def register_robot(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.register_robot(RegisterRequest(args["image"]), ctx.cancel)


def locate(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    colors = tuple(args["colors"]) if args["colors"] is not None else None
    return ctx.cell.locate(LocateRequest(args["image"], colors=colors), ctx.cancel)


def move(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.move(
        joints_deg=args["joints_deg"],
        pose=args["pose"],
        matrix=args["matrix"],
        speed_deg_s=args["speed_deg_s"],
        speed_mm_s=args["speed_mm_s"],
        cancel=ctx.cancel,
    )


def sort(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    colors = tuple(args["colors"]) if args["colors"] is not None else None
    request = SortRequest(args["max_objects"], colors)
    return ctx.cell.sort(request, ctx.cancel, ctx.progress)


def check(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.drift.check(args["image"])


def adopt(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.adopt(AdoptRequest(args["camera"], args["system"]))


def acknowledge_drift(ctx: Context, args: dict[str, Any]) -> dict[str, Any]:
    return ctx.cell.drift.acknowledge()


HANDLERS: dict[str, Handler] = {
    "status": status,
    "capture": capture,
    "laser": laser,
    "calibrate": calibrate,
    "map": map_scene,
    "register_robot": register_robot,
    "locate": locate,
    "move": move,
    "sort": sort,
    "check": check,
    "acknowledge_drift": acknowledge_drift,
    "adopt": adopt,
}
