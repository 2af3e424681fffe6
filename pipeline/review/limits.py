"""Request limits, applied before routing, authentication and body parsing (a plain ASGI
middleware: what a front proxy would also enforce; see docs for the nginx equivalents).

- headers over MAX_HEADER_BYTES in all: 431, nothing read;
- a body over MAX_BODY_BYTES: 413, refused on its Content-Length before a byte is read, or
  as soon as a chunked body passes the limit (the app never sees the rest).
The review API's largest legitimate body is an adjudication (a 4,000-character rationale and
four fields): a few KiB. Slow clients are bounded by uvicorn's keep-alive timeout only; a
deployment puts a proxy with header/body read timeouts in front (client_header_timeout,
client_body_timeout in nginx).
"""

from __future__ import annotations

import json

MAX_BODY_BYTES = 64 * 1024
MAX_HEADER_BYTES = 16 * 1024


class _TooLarge(Exception):
    pass


def _answer(status: int, detail: str):
    body = json.dumps({"detail": detail}).encode()
    return [{"type": "http.response.start", "status": status,
             "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                         (b"connection", b"close")]},
            {"type": "http.response.body", "body": body}]


class RequestLimits:
    def __init__(self, app, max_body: int = MAX_BODY_BYTES, max_headers: int = MAX_HEADER_BYTES):
        self.app, self.max_body, self.max_headers = app, max_body, max_headers

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers = scope.get("headers") or []
        if sum(len(k) + len(v) for k, v in headers) > self.max_headers:
            return await self._send(send, 431, f"request headers over {self.max_headers} bytes")
        length = next((v for k, v in headers if k == b"content-length"), None)
        if length is not None and (not length.isdigit() or int(length) > self.max_body):
            return await self._send(send, 413, f"request body over {self.max_body} bytes")
        seen, started = 0, False

        async def limited_receive():
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.max_body:
                    raise _TooLarge
            return message

        async def tracking_send(message):
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except _TooLarge:
            if not started:
                await self._send(send, 413, f"request body over {self.max_body} bytes")

    @staticmethod
    async def _send(send, status: int, detail: str) -> None:
        for message in _answer(status, detail):
            await send(message)
