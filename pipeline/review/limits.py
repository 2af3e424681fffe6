"""Request limits, applied before routing, authentication and body parsing: what a front
proxy would also enforce (docs/security.md gives the nginx equivalents).

Two layers, each doing what only it can:
- the HTTP protocol (`BoundedHttpProtocol`, uvicorn's httptools protocol with a clock):
  a request's headers must arrive within HEADER_TIMEOUT_S of its first byte (or of the
  connection) and stay under MAX_HEADER_BYTES while they arrive; otherwise 408 or 431 and
  the connection is closed. The app never sees such a request, so no ASGI code could;
- the ASGI app (`RequestLimits`): headers over MAX_HEADER_BYTES in all: 431; a body over
  MAX_BODY_BYTES: 413, refused on its Content-Length before a byte is read, or as soon as a
  chunked body passes the limit; a body not delivered within BODY_TIMEOUT_S of the request
  reaching the app: 408. An answer sent before the body was read (a 401, say: bodies are
  read only after authentication) closes the connection, so nobody can keep it open by
  trickling the rest of a body nobody reads.
The review API's largest legitimate body is an adjudication (a 4,000-character rationale and
four fields): a few KiB. Idle keep-alive connections are closed by uvicorn after
`timeout_keep_alive` (5 s).
"""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

MAX_BODY_BYTES = 64 * 1024
MAX_HEADER_BYTES = 16 * 1024
HEADER_TIMEOUT_S = 10.0
BODY_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Limits:
    max_body: int = MAX_BODY_BYTES
    max_headers: int = MAX_HEADER_BYTES
    header_timeout_s: float = HEADER_TIMEOUT_S
    body_timeout_s: float = BODY_TIMEOUT_S


def _raw_answer(status: int, reason: bytes, detail: str) -> bytes:
    body = json.dumps({"detail": detail}).encode()
    return (b"HTTP/1.1 %d %s\r\ncontent-type: application/json\r\ncontent-length: %d\r\n"
            b"connection: close\r\n\r\n%s" % (status, reason, len(body), body))


class BoundedHttpProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol, with a deadline and a size cap on each request's headers.

    The clock starts when the connection opens and again when a request's first byte
    arrives; it stops when its headers are complete. Header bytes are counted per chunk
    read from the socket, so the cap holds to within one read (at most 256 KiB)."""

    header_timeout_s = HEADER_TIMEOUT_S
    max_header_bytes = MAX_HEADER_BYTES

    def connection_made(self, transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._in_headers, self._header_bytes = True, 0
        self._deadline: asyncio.TimerHandle | None = None
        self._arm()

    def _arm(self) -> None:
        if self._deadline is None:
            self._deadline = self.loop.call_later(self.header_timeout_s, self._too_slow)

    def _disarm(self) -> None:
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None

    def data_received(self, data: bytes) -> None:
        if self._in_headers:
            self._header_bytes += len(data)
        super().data_received(data)
        if self._in_headers and self._header_bytes > self.max_header_bytes and not self.transport.is_closing():
            self._refuse(431, b"Request Header Fields Too Large", f"request headers over {self.max_header_bytes} bytes")

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._in_headers, self._header_bytes = True, 0
        self._arm()

    def on_headers_complete(self) -> None:
        self._in_headers = False
        self._disarm()
        super().on_headers_complete()

    def connection_lost(self, exc) -> None:
        self._disarm()
        super().connection_lost(exc)

    def _too_slow(self) -> None:
        self._deadline = None
        if self._in_headers and not self.transport.is_closing():
            self._refuse(408, b"Request Timeout", f"request headers not complete within {self.header_timeout_s:g} s")

    def _refuse(self, status: int, reason: bytes, detail: str) -> None:
        self._disarm()
        self.transport.write(_raw_answer(status, reason, detail))
        self.transport.close()


def protocol_for(limits: Limits) -> type[BoundedHttpProtocol]:
    """The protocol class with these limits (the defaults: `BoundedHttpProtocol` itself,
    which worker processes import by name)."""
    if (limits.header_timeout_s, limits.max_headers) == (HEADER_TIMEOUT_S, MAX_HEADER_BYTES):
        return BoundedHttpProtocol
    return type("BoundedHttpProtocol", (BoundedHttpProtocol,),
                {"header_timeout_s": limits.header_timeout_s, "max_header_bytes": limits.max_headers})


class _TooLarge(Exception):
    pass


def _answer(status: int, detail: str):
    body = json.dumps({"detail": detail}).encode()
    return [{"type": "http.response.start", "status": status,
             "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                         (b"connection", b"close")]},
            {"type": "http.response.body", "body": body}]


class _TooSlow(Exception):
    pass


class RequestLimits:
    def __init__(self, app, limits: Limits = Limits()):
        self.app, self.limits = app, limits
        self.max_body, self.max_headers = limits.max_body, limits.max_headers

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers = scope.get("headers") or []
        if sum(len(k) + len(v) for k, v in headers) > self.max_headers:
            return await self._send(send, 431, f"request headers over {self.max_headers} bytes")
        length = next((v for k, v in headers if k == b"content-length"), None)
        if length is not None and (not length.isdigit() or int(length) > self.max_body):
            return await self._send(send, 413, f"request body over {self.max_body} bytes")
        chunked = any(k == b"transfer-encoding" for k, _ in headers)
        seen, started = 0, False
        body_left = chunked or (length is not None and int(length) > 0)
        deadline = time.monotonic() + self.limits.body_timeout_s

        async def limited_receive():
            nonlocal seen, body_left
            if not body_left:
                return await receive()  # nothing more to read: wait for the disconnect as usual
            try:
                message = await asyncio.wait_for(receive(), max(0.0, deadline - time.monotonic()))
            except asyncio.TimeoutError:
                raise _TooSlow from None
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                body_left = bool(message.get("more_body"))
                if seen > self.max_body:
                    raise _TooLarge
            return message

        async def tracking_send(message):
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
                if body_left:  # answered before the body was read: close, never drain it
                    message = {**message, "headers": [*message.get("headers", []), (b"connection", b"close")]}
            await send(message)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _TooLarge:
            if not started:
                await self._send(send, 413, f"request body over {self.max_body} bytes")
        except _TooSlow:
            if not started:
                await self._send(send, 408, f"request body not complete within {self.limits.body_timeout_s:g} s")

    @staticmethod
    async def _send(send, status: int, detail: str) -> None:
        for message in _answer(status, detail):
            await send(message)
