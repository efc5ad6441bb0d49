"""Each protocol command as a function of the cell: `handler(ctx, request) -> result dict`.

`request` is the command's request record (`pipeline.requests`), built from its checked
arguments; None for a command without arguments. Handlers run in worker threads (never in the
event loop) and may block on devices; the server bounds them with timeouts. Commands that act
on the service itself (stop, estop, reset, shutdown) live in the server, which owns the state
machine.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from omnisort_hw.cell.cell import Cell
from omnisort_hw.pipeline.requests import (
    AdoptRequest,
    CalibrateRequest,
    CaptureRequest,
    CheckRequest,
    DetectRequest,
    GeometryRequest,
    HistoryRequest,
    LaserRequest,
    LocateRequest,
    MapRequest,
    MoveRequest,
    PictureRequest,
    RegisterRequest,
    SortRequest,
    ViewRequest,
    ViewsRequest,
)
from omnisort_hw.service.protocol import describe_commands
from omnisort_hw.service.status_reply import ServiceStatus, StatusReply
from omnisort_hw.wire_records import to_wire


@dataclass
class Context:
    """What a handler gets besides its request."""

    cell: Cell
    cancel: threading.Event
    service_status: Callable[[], ServiceStatus]
    progress: Callable[[dict[str, Any]], None] | None = None


Reply = Mapping[str, object]
"""A command's result: a use case's typed reply (`pipeline.replies`) or the cell's answer."""
Handler = Callable[[Context, Any], Reply]


def status(ctx: Context, _request: None) -> StatusReply:
    """Service state, job, devices and calibration health."""
    service, cell = ctx.service_status(), ctx.cell.status()
    allowed = bool(cell["calibration"]["motion_allowed"]) and service["state"] != "fault"
    return {**service, **cell, "motion_allowed": allowed}


def describe(ctx: Context, _request: None) -> Reply:
    return to_wire(describe_commands())


def view(ctx: Context, request: ViewRequest) -> Reply:
    return to_wire(ctx.cell.view(request.width, request.quality))


def detect(ctx: Context, request: DetectRequest) -> Reply:
    return to_wire(ctx.cell.detect(request))


def views(ctx: Context, request: ViewsRequest) -> Reply:
    from omnisort_hw.pipeline import views as kept_views

    return to_wire(kept_views.run(ctx.cell.jobs, request).reply())


def history(ctx: Context, request: HistoryRequest) -> Reply:
    from omnisort_hw.pipeline import calibration_history

    return to_wire(calibration_history.run(ctx.cell.jobs, request).reply())


def geometry(ctx: Context, request: GeometryRequest) -> Reply:
    from omnisort_hw.pipeline import cell_geometry

    return to_wire(cell_geometry.run(ctx.cell.jobs, request).reply())


def picture(ctx: Context, request: PictureRequest) -> Reply:
    return to_wire(ctx.cell.picture(request.path, request.width, request.quality))


def capture(ctx: Context, request: CaptureRequest) -> Reply:
    return to_wire(ctx.cell.capture(request.encoding, request.format, request.laser))


def laser(ctx: Context, request: LaserRequest) -> Reply:
    return to_wire(ctx.cell.laser(request.on))


def calibrate(ctx: Context, request: CalibrateRequest) -> Reply:
    if request.what == "intrinsics":
        from omnisort_hw.pipeline.intrinsics import image_files

        images = tuple(image_files(str(request.folder)))
        return to_wire(ctx.cell.jobs.calibrate_intrinsics(request.intrinsics(images), ctx.cancel))
    return to_wire(ctx.cell.jobs.calibrate_extrinsics(request, ctx.cancel))


def map_scene(ctx: Context, request: MapRequest) -> Reply:
    return to_wire(ctx.cell.jobs.map_scene(request, ctx.cancel))


def register_robot(ctx: Context, request: RegisterRequest) -> Reply:
    return to_wire(ctx.cell.jobs.register_robot(request, ctx.cancel))


def locate(ctx: Context, request: LocateRequest) -> Reply:
    return to_wire(ctx.cell.jobs.locate(request, ctx.cancel))


def move(ctx: Context, request: MoveRequest) -> Reply:
    return to_wire(ctx.cell.move(request, ctx.cancel))


def sort(ctx: Context, request: SortRequest) -> Reply:
    return to_wire(ctx.cell.jobs.sort(request, ctx.cancel, ctx.progress))


def check(ctx: Context, request: CheckRequest) -> Reply:
    return to_wire(ctx.cell.drift.check(request.image))


def adopt(ctx: Context, request: AdoptRequest) -> Reply:
    return to_wire(ctx.cell.jobs.adopt(request))


def acknowledge_drift(ctx: Context, _request: None) -> Reply:
    return to_wire(ctx.cell.drift.acknowledge())


HANDLERS: dict[str, Handler] = {
    "status": status,
    "describe": describe,
    "view": view,
    "picture": picture,
    "detect": detect,
    "views": views,
    "history": history,
    "geometry": geometry,
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
