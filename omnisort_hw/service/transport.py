"""The service's connections: read request lines (bounded, with idle and line timeouts),
admit clients per peer, check tokens, answer each request with its id and forward a job's
progress events; a slow client is dropped rather than allowed to hold the loop.

`Transport` is a part of `server.Service` (its base class), kept apart because this is the
wire and the rest of the service is its state, its jobs and its life cycle.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from typing import TYPE_CHECKING, Any

from omnisort_hw.service import protocol as proto
from omnisort_hw.service.connection import (
    TOO_LONG,
    Admission,
    IdleTimeoutError,
    LineReader,
    LineTimeoutError,
    peer_host,
)
from omnisort_hw.service.error_replies import error_from_exception
from omnisort_hw.service.protocol import Emit

if TYPE_CHECKING:
    from omnisort_hw.config.service import ServiceConfig

log = logging.getLogger("omnisort.service")

SAFETY_INFLIGHT_PER_CLIENT = 4
MAX_SAFETY_LINE_BYTES = 4096


class Transport:
    """The connection side of `server.Service` (see the module doc)."""

    config: ServiceConfig
    counters: dict[str, int]
    errors_by_code: dict[str, int]
    last_error: tuple[str, str, float] | None
    _admission: Admission
    _clients: set[asyncio.StreamWriter]

    if TYPE_CHECKING:  # defined by `Service`

        async def dispatch(
            self, req: proto.Request, emit: Emit | None = None
        ) -> dict[str, Any]: ...

        def _authorize(
            self, spec: proto.Command, token: str | None, rid: int | str | None
        ) -> None: ...

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        host = peer_host(writer.get_extra_info("peername"))
        self.counters["connections"] += 1
        refusal = self._admission.admit(host)
        if refusal is not None:
            await self._overflow(reader, writer, host, refusal)
            return
        write_lock = asyncio.Lock()
        self._clients.add(writer)
        slots = asyncio.Semaphore(self.config.max_inflight_per_client)
        safety_slots = asyncio.Semaphore(SAFETY_INFLIGHT_PER_CLIENT)
        tasks: set[asyncio.Task[None]] = set()
        lines = LineReader(
            reader,
            self.config.max_line_bytes,
            self.config.line_timeout_s,
            self.config.idle_timeout_s or None,
            busy=lambda: bool(tasks),
        )
        try:
            while (line := await lines.next()) is not None and not writer.is_closing():
                self.counters["requests"] += 1
                if line is TOO_LONG:
                    msg = f"request line longer than {self.config.max_line_bytes} bytes; discarded"
                    await self._send(
                        writer, write_lock, proto.error_reply(None, proto.BAD_REQUEST, msg)
                    )
                    continue
                assert isinstance(line, bytes)
                try:
                    req = proto.parse_request(line, self._authorize)
                except proto.ProtocolError as exc:
                    await self._send(writer, write_lock, proto.reply_for(exc))
                    continue
                # Stop and estop never wait behind the client's other requests.
                slot = safety_slots if req.command.kind == "safety" else slots
                await slot.acquire()
                task = asyncio.create_task(self._serve(req, writer, write_lock, slot))
                tasks.add(task)
                task.add_done_callback(tasks.discard)
        except (LineTimeoutError, IdleTimeoutError) as exc:
            log.info("closing connection from %s: %s", host, exc)
            await self._send(
                writer, write_lock, proto.error_reply(None, proto.BAD_REQUEST, f"{exc}; closing")
            )
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        except asyncio.CancelledError:
            # The shutdown cancels the open connections. The handler ends normally after its
            # clean-up: on Python 3.11 asyncio's stream callback asks a cancelled handler
            # task for its exception, which raises and is logged as a traceback.
            log.info("closing connection from %s: the service is stopping", host)
        except Exception:
            log.exception("connection from %s failed", host)
        finally:
            if tasks:
                with contextlib.suppress(asyncio.CancelledError):  # cancelled while waiting
                    await asyncio.wait(tasks, timeout=self.config.write_timeout_s)
            self._clients.discard(writer)
            self._admission.release(host)
            writer.close()
            with contextlib.suppress(Exception, asyncio.CancelledError):
                await asyncio.wait_for(writer.wait_closed(), 2.0)

    async def _overflow(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, host: str, refusal: str
    ) -> None:
        """A connection over a limit: one `stop`/`estop` line is still served (the reserved
        path); anything else, or nothing within the grace period, gets `busy` and is closed."""
        lock = asyncio.Lock()
        busy = proto.error_reply(
            None, proto.BUSY, f"{refusal}; try again later (stop and estop are still served)"
        )
        if not self._admission.enter_overflow():
            log.warning("refusing a connection from %s at once: %s", host, refusal)
            await self._send(writer, lock, busy)
            writer.close()
            return
        try:
            lines = LineReader(reader, MAX_SAFETY_LINE_BYTES, self.config.overflow_grace_s, None)
            try:
                line = await asyncio.wait_for(lines.next(), self.config.overflow_grace_s)
            except (TimeoutError, LineTimeoutError, ConnectionError):
                line = None
            req = None
            if isinstance(line, bytes):
                with contextlib.suppress(proto.ProtocolError):
                    req = proto.parse_request(line, self._authorize)
            if req is not None and req.command.kind == "safety":
                self.counters["requests"] += 1
                log.warning("%s from %s served on the reserved path (%s)", req.cmd, host, refusal)
                await self._send(writer, lock, await self._reply(req))
            else:
                await self._send(writer, lock, busy)
        finally:
            self._admission.leave_overflow()
            writer.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(writer.wait_closed(), 2.0)

    async def _send(
        self, writer: asyncio.StreamWriter, lock: asyncio.Lock, reply: dict[str, Any]
    ) -> None:
        if reply.get("ok") is False:
            self.counters["errors"] += 1
            error = reply.get("error") or {}
            code = str(error.get("code", "?"))
            self.errors_by_code[code] = self.errors_by_code.get(code, 0) + 1
            self.last_error = (code, str(error.get("message", "")), time.monotonic())
        data = proto.encode(reply)
        async with lock:
            if writer.is_closing():
                return
            writer.write(data)
            try:
                await asyncio.wait_for(writer.drain(), self.config.write_timeout_s)
            except TimeoutError:
                self.counters["slow_clients_dropped"] += 1
                log.warning(
                    "client %s did not read its replies for %g s; disconnected",
                    peer_host(writer.get_extra_info("peername")),
                    self.config.write_timeout_s,
                )
                writer.transport.abort()
            except ConnectionError:
                writer.close()

    async def _reply(self, req: proto.Request, emit: Emit | None = None) -> dict[str, Any]:
        try:
            return await self.dispatch(req, emit)
        except proto.ProtocolError as exc:
            return proto.reply_for(exc, req.id)
        except Exception as exc:
            log.exception("request %r failed", req.cmd)
            code, msg, details = error_from_exception(exc)
            return proto.error_reply(req.id, code, msg, **details)

    async def _serve(
        self,
        req: proto.Request,
        writer: asyncio.StreamWriter,
        lock: asyncio.Lock,
        slot: asyncio.Semaphore,
    ) -> None:
        """Run one request and write its reply; the client's slot is freed only once the reply
        is written (or the client dropped), so a client that does not read stops being read."""
        sent: list[asyncio.Future[None]] = []

        def emit(event: dict[str, Any]) -> None:
            """Write one progress event (in the loop thread); the reply waits for them all."""
            line = proto.progress_event(req.id, event)
            sent.append(asyncio.ensure_future(self._send(writer, lock, line)))

        try:
            reply = await self._reply(req, emit if req.progress else None)
            await asyncio.gather(*sent, return_exceptions=True)
            await self._send(writer, lock, reply)
        finally:
            slot.release()
