"""The typed face of the client: one method per protocol command, each written once over one
`execute()` (as pymodbus's client mixin writes each request once).

A method takes the command's request record (`pipeline.requests`, the one declaration of its
arguments) and returns the service's `result`, typed as the use case's reply
(`pipeline.replies`) where the command is one; an error reply raises `CommandError` with its
typed code, message and field. A job's progress events reach `on_event` as they arrive.
`tests/service/test_typed_client.py` checks that every command of the protocol has its method.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar, cast, overload

from omnisort_hw.pipeline.replies import (
    AcknowledgeReply,
    AdoptReply,
    CalibrateReply,
    CaptureReply,
    DescribeReply,
    DetectReply,
    DriftReply,
    ExtrinsicsReply,
    GeometryReply,
    HistoryReply,
    IntrinsicsReply,
    LaserReply,
    LocateReply,
    MapReply,
    MoveReply,
    PictureFileReply,
    RegisterReply,
    ResetReply,
    ShutdownReply,
    SortReply,
    StopReply,
    ViewReply,
    ViewsReply,
)
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
    ResetRequest,
    SortRequest,
    ViewRequest,
    ViewsRequest,
)
from omnisort_hw.request_fields import wire_args
from omnisort_hw.service.status_reply import StatusReply
from omnisort_hw.wire_records import WireError, from_wire

Result = dict[str, Any]
OnEvent = Callable[[dict[str, Any]], None] | None
R = TypeVar("R")
R_co = TypeVar("R_co", covariant=True)
T = TypeVar("T")
Q = TypeVar("Q")


class CommandError(Exception):
    """The service answered a command with an error: its `code` (protocol.ERROR_CODES), its
    message, and the details it gave (`field` for a bad argument)."""

    def __init__(self, command: str, error: dict[str, Any]) -> None:
        self.command = command
        self.code = str(error.get("code", "internal"))
        self.message = str(error.get("message", ""))
        self.details = {k: v for k, v in error.items() if k not in ("code", "message")}
        super().__init__(f"{command}: {self.code}: {self.message}")


class ClientError(Exception):
    """The service could not be reached or did not answer in time."""

    code = "client_error"


class ReplyError(ClientError):
    """The service's reply does not fit the command's reply record (a service of another
    version): names the command, the record and the field."""

    code = "reply_mismatch"


def _read(record: type[T], command: str, result: Result) -> T:
    try:
        return from_wire(record, result)
    except WireError as exc:
        raise ReplyError(f"{command}: the service's reply does not fit {exc}") from None


class CellCommands:
    """Mixed into a client that provides `execute(cmd, args, on_event=None) -> result`."""

    def execute(
        self, cmd: str, args: dict[str, Any] | None = None, on_event: OnEvent = None
    ) -> Result:
        raise NotImplementedError

    def status(self) -> StatusReply:
        return cast(StatusReply, self.execute("status"))

    def describe(self) -> DescribeReply:
        return _read(DescribeReply, "describe", self.execute("describe"))

    def view(self, request: ViewRequest | None = None) -> ViewReply:
        return _read(ViewReply, "view", self.execute("view", wire_args(request)))

    def picture(self, request: PictureRequest) -> PictureFileReply:
        return _read(PictureFileReply, "picture", self.execute("picture", wire_args(request)))

    def detect(self, request: DetectRequest | None = None) -> DetectReply:
        return _read(DetectReply, "detect", self.execute("detect", wire_args(request)))

    def views(self, request: ViewsRequest | None = None) -> ViewsReply:
        return _read(ViewsReply, "views", self.execute("views", wire_args(request)))

    def history(self, request: HistoryRequest | None = None) -> HistoryReply:
        return _read(HistoryReply, "history", self.execute("history", wire_args(request)))

    def geometry(self, request: GeometryRequest | None = None) -> GeometryReply:
        return _read(GeometryReply, "geometry", self.execute("geometry", wire_args(request)))

    def capture(self, request: CaptureRequest | None = None) -> CaptureReply:
        return _read(CaptureReply, "capture", self.execute("capture", wire_args(request)))

    def laser(self, request: LaserRequest | None = None) -> LaserReply:
        return _read(LaserReply, "laser", self.execute("laser", wire_args(request)))

    def calibrate(self, request: CalibrateRequest, on_event: OnEvent = None) -> CalibrateReply:
        reply = self.execute("calibrate", wire_args(request), on_event)
        if request.what == "intrinsics":
            return _read(IntrinsicsReply, "calibrate", reply)
        return _read(ExtrinsicsReply, "calibrate", reply)

    def map(self, request: MapRequest | None = None, on_event: OnEvent = None) -> MapReply:
        return _read(MapReply, "map", self.execute("map", wire_args(request), on_event))

    def register_robot(
        self, request: RegisterRequest | None = None, on_event: OnEvent = None
    ) -> RegisterReply:
        reply = self.execute("register_robot", wire_args(request), on_event)
        return _read(RegisterReply, "register_robot", reply)

    def locate(self, request: LocateRequest | None = None, on_event: OnEvent = None) -> LocateReply:
        return _read(LocateReply, "locate", self.execute("locate", wire_args(request), on_event))

    def move(self, request: MoveRequest, on_event: OnEvent = None) -> MoveReply:
        return _read(MoveReply, "move", self.execute("move", wire_args(request), on_event))

    def sort(self, request: SortRequest | None = None, on_event: OnEvent = None) -> SortReply:
        return _read(SortReply, "sort", self.execute("sort", wire_args(request), on_event))

    def check(self, request: CheckRequest | None = None, on_event: OnEvent = None) -> DriftReply:
        return _read(DriftReply, "check", self.execute("check", wire_args(request), on_event))

    def adopt(self, request: AdoptRequest, on_event: OnEvent = None) -> AdoptReply:
        return _read(AdoptReply, "adopt", self.execute("adopt", wire_args(request), on_event))

    def acknowledge_drift(self) -> AcknowledgeReply:
        return _read(AcknowledgeReply, "acknowledge_drift", self.execute("acknowledge_drift"))

    def stop(self) -> StopReply:
        return _read(StopReply, "stop", self.execute("stop"))

    def estop(self) -> StopReply:
        return _read(StopReply, "estop", self.execute("estop"))

    def reset(self, request: ResetRequest | None = None) -> ResetReply:
        return _read(ResetReply, "reset", self.execute("reset", wire_args(request)))

    def shutdown(self) -> ShutdownReply:
        return _read(ShutdownReply, "shutdown", self.execute("shutdown"))


@dataclass(frozen=True)
class Call(Generic[R_co]):
    """One command to send later on a connection chosen then (a door that opens its own, as
    the page's link and its job runner do): a `CellCommands` method, whose name is the
    protocol's command, and its request record (None: the method's default). Made by
    `call_of`, which checks the record against the method's, so no door names a command by a
    string."""

    method: Callable[..., R_co]
    request: object = None

    @property
    def command(self) -> str:
        """The protocol's name of the command (`tests/service/test_typed_client.py` checks
        that each method is named for its command)."""
        return str(self.method.__name__)

    def send(self, client: CellCommands) -> R_co:
        """The command sent on `client`: the service's typed reply."""
        if self.request is None:
            return self.method(client)
        return self.method(client, self.request)


@overload
def call_of(method: Callable[[CellCommands], R]) -> Call[R]: ...


@overload
def call_of(method: Callable[[CellCommands, Q], R], request: Q) -> Call[R]: ...


def call_of(method: Callable[..., R], request: Any = None) -> Call[R]:
    """The call of `method` (e.g. `CellCommands.laser`) with `request` (its record type)."""
    return Call(method, request)
