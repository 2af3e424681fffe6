"""The five requests of every reviewed item, answered before FastAPI's routing.

Inputs: the ASGI request; the engine, settings and run folder of the app.
Outputs: the same answers as the FastAPI routes of `api.py` for
  POST /api/queue/next   GET /api/items/{id}   GET /api/items/{id}/frames|evidence
  POST /api/items/{id}/review
Why: with 20 reviewers back to back on 2 cores the server is CPU-bound, and routing,
dependency solving and request parsing cost more than the answers (prebuilt reads, cached
tables). This plain ASGI middleware does only the plain case: anything else (another path
or method, a path that is not a plain number, a body that is not `application/json` or
fails the schema) goes on to FastAPI unchanged, body included, so every error answer
stays FastAPI's. The answers come from the same functions the FastAPI routes call.
Invariants: the same user check (`auth.authenticate`), the same errors for the workflow's
refusals (`ReviewError.body()`), and the security headers (this middleware sits inside
`SecurityHeaders`).
"""

from __future__ import annotations

import json
import re

from pydantic import ValidationError
from starlette.requests import cookie_parser

from pipeline.review import auth
from pipeline.review.errors import ReviewError

_ROUTES = re.compile(r"^/api/(?:queue/(next)|items/(\d{1,18})(?:/(frames|evidence|review))?)$")
_JSON = [(b"content-type", b"application/json")]
_TABLE_HEADERS = [(b"cache-control", b"private, max-age=300")]


def _headers(scope) -> dict[bytes, bytes]:
    """Request headers by lower-case name; a repeated one: its first value (as Starlette's
    `headers.get`); cookies: all of them joined (as Starlette's `cookies`)."""
    out: dict[bytes, bytes] = {}
    for k, v in scope["headers"]:
        if k == b"cookie" and k in out:
            out[k] += b"; " + v
        else:
            out.setdefault(k, v)
    return out


def _kind(method: str, m) -> str | None:
    nxt, sub = m.group(1), m.group(3)
    if nxt:
        return "next" if method == "POST" else None
    if sub in ("frames", "evidence"):
        return sub if method == "GET" else None
    if sub == "review":
        return "review" if method == "POST" else None
    return "item" if method == "GET" else None


class FastLane:
    def __init__(self, app, *, handlers):
        self.app = app
        self.h = handlers  # api.Handlers: the answers the FastAPI routes give too

    async def __call__(self, scope, receive, send):
        m = _ROUTES.match(scope["path"]) if scope["type"] == "http" and not scope.get("root_path") else None
        kind = _kind(scope["method"], m) if m is not None else None
        if kind is None:
            return await self.app(scope, receive, send)
        headers = _headers(scope)
        decision = None
        if kind == "review":
            ctype = headers.get(b"content-type", b"").split(b";")[0].strip().lower()
            body, more = await _read(receive)
            if body is None:
                return  # the client went away
            if ctype == b"application/json" and not more:
                decision = parse(self.h.decision_model, body)
            if decision is None:  # FastAPI answers (its 422), reading the same body
                return await self.app(scope, _replay(body, more, receive), send)
        extra: list = []
        try:
            authz = headers.get(b"authorization", b"").decode("latin-1")
            bearer = authz[7:].strip() if authz.lower().startswith("bearer ") else None
            raw_cookie = headers.get(b"cookie")
            cookie = cookie_parser(raw_cookie.decode("latin-1")).get(auth.COOKIE) if raw_cookie else None
            csrf = headers.get(auth.CSRF_HEADER.encode())
            p = auth.authenticate(self.h.engine, scope["method"], bearer, cookie,
                                  csrf.decode("latin-1") if csrf is not None else None)
            if kind == "next":
                out = await self.h.next_item(p)
            elif kind == "item":
                out = self.h.item(int(m.group(2)), p)
            elif kind == "review":
                out = await self.h.review(int(m.group(2)), decision, p)
            else:
                out = await self.h.table(int(m.group(2)), kind)
                extra = _TABLE_HEADERS
            status = 200
        except ReviewError as e:  # as the app's exception handler answers it
            status, out, extra = e.status, dumps(e.body()), []
        await send({"type": "http.response.start", "status": status,
                    "headers": [(b"content-length", str(len(out)).encode()), *_JSON, *extra]})
        await send({"type": "http.response.body", "body": out})


def dumps(obj) -> bytes:
    # as starlette's JSONResponse encodes
    return json.dumps(obj, ensure_ascii=False, allow_nan=False, indent=None, separators=(",", ":")).encode("utf-8")


async def _read(receive) -> tuple[bytes | None, bool]:
    """The request body (None if the client went away), read up to 64 KiB: `more` says it
    goes on (then FastAPI reads the rest)."""
    chunks, size = [], 0
    while True:
        msg = await receive()
        if msg["type"] != "http.request":
            return None, False
        chunk = msg.get("body", b"")
        chunks.append(chunk)
        size += len(chunk)
        if not msg.get("more_body", False):
            return b"".join(chunks), False
        if size > 65536:
            return b"".join(chunks), True


def _replay(body: bytes, more: bool, receive):
    sent = False

    async def again():
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": more}
        return await receive()

    return again


def parse(model, body: bytes):
    """`model` from a JSON body as FastAPI validates it (json.loads, then python mode), or None."""
    try:
        return model.model_validate(json.loads(body))
    except (ValueError, ValidationError):
        return None
