"""The live view: everything the service logs, streamed to a rerun gRPC server as it happens.

A second, long-lived recording with a `GrpcServerSink` mirrors the run log (the `.rrd` files
go on being written and rotated; the live stream outlives the rotation). The server keeps at
most `live_memory_limit` of data for late viewers and drops the oldest beyond it, so a
day-long run stays bounded. With `live_web_port` rerun's web viewer is served too.
`omnisort review --live HOST:PORT` (or any rerun viewer) connects to it.
"""

from __future__ import annotations

import logging
import uuid

from omnisort_hw.config.live_view import LiveViewConfig
from omnisort_hw.runlog import RunLog

log = logging.getLogger("omnisort.live")


def grpc_url(host: str, port: int) -> str:
    """The viewer URL of a rerun gRPC server."""
    return f"rerun+http://{host}:{port}/proxy"


class LiveView:
    """The gRPC server of one service and the recording that feeds it."""

    def __init__(self, config: LiveViewConfig, application_id: str = "omnisort") -> None:
        import rerun as rr

        self.config = config
        self.recording = rr.RecordingStream(application_id, recording_id=uuid.uuid4())
        sink = rr.GrpcServerSink(config.host, config.port, server_memory_limit=config.memory_limit)
        self.recording.set_sinks(sink)
        self.url: str = sink.uri
        self.web_url: str | None = None
        if config.web_port is not None:
            rr.serve_web_viewer(web_port=config.web_port, open_browser=False, connect_to=self.url)
            self.web_url = f"http://{config.host}:{config.web_port}"
        log.info("live view on %s (server memory limit %s)", self.url, config.memory_limit)

    def attach(self, runlog: RunLog) -> None:
        """Mirror `runlog` (and its later files) to the live stream."""
        runlog.set_mirror(self.recording)

    def close(self, runlog: RunLog | None = None) -> None:
        if runlog is not None:
            runlog.set_mirror(None)
        try:
            self.recording.flush()
        finally:
            self.recording.disconnect()


def start_live_view(config: LiveViewConfig, runlog: RunLog) -> LiveView | None:
    """The live view of `[logging]`, attached to `runlog`, or None when `live` is off."""
    if not config.enabled:
        return None
    view = LiveView(config)
    view.attach(runlog)
    return view
