"""The review server: the app factory (JSON API, the web page `review_ui/`, the run's media).

Inputs: the run folder, a database engine, the queue settings.
Outputs: a FastAPI app. Routes, one router per resource under `routes/` (all JSON unless noted):
  session:      POST /api/login {token} -> session cookie + csrf   POST /api/logout   GET /api/me
  queue:        GET /api/queue (with `progress`)   GET /api/progress   POST /api/queue/next
  items:        GET /api/items/{id}   POST .../lease   POST .../review (accept | revise | flag)
  adjudication: GET /api/items/{id}/adjudication   POST .../claim   POST .../adjudication   GET .../history
  admin:        GET /api/status (and, with `docs=True`, /api/docs and /api/openapi.json)
  media:        GET /api/items/{id}/evidence, /frames   GET /media/<path under the run folder> (file)
  GET / (the page)
Invariants: every route but login and the page needs a user (`deps`), the OpenAPI docs too;
an item's reviews stay hidden while they are being collected (`blindness`);
writes through the cookie need the CSRF header; errors are `{"detail", "field"?, "current"?}`
with 401/403/404/409/415/422; a request body that fails the schema is a 422 whose `field`
names the bad field, and no error repeats a secret (a token field, a whole body, a long value).
Routes are thin: the rules live in `workflow`, `adjudication`, `views` and `auth` only.
"""

from __future__ import annotations

from contextlib import asynccontextmanager
from pathlib import Path

import anyio
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.staticfiles import StaticFiles
from sqlalchemy.engine import Engine

from pipeline.review.deps import ServerContext
from pipeline.review.errors import ReviewError
from pipeline.review.limits import Limits, RequestLimits
from pipeline.review.routes import adjudication, admin, items, media, queue, session
from pipeline.review.workflow import QueueSettings

UI_DIR = Path(__file__).resolve().parents[2] / "review_ui"
# threads per server process for the plain `def` routes and dependencies (anyio's default is
# 40): with dozens runnable, the one holding SQLite's write lock waits for the GIL behind the
# others and every writer queues longer; requests beyond these wait, without CPU, in the loop
REQUEST_THREADS = 8


@asynccontextmanager
async def _lifespan(_app):
    anyio.to_thread.current_default_thread_limiter().total_tokens = REQUEST_THREADS
    yield

SECRET_FIELDS = {"token", "csrf", "password"}


def _echo(field: str, value) -> str:
    """What of a rejected input an error may repeat: numbers and short words of non-secret
    fields; never a whole body (it may hold a token) nor a secret field."""
    if field in SECRET_FIELDS or field == "body":
        return ""
    if isinstance(value, (bool, int, float)) or value is None:
        return f" (got {value!r})"
    if isinstance(value, str) and len(value) <= 40:
        return f" (got {value!r})"
    return ""


def _validation_error(_req: Request, exc: RequestValidationError) -> JSONResponse:
    errors = []
    for e in exc.errors():
        loc = [str(p) for p in e["loc"] if p not in ("body",)]
        field = next((p for p in reversed(loc) if not p.isdigit()), "body")
        got = _echo(field, e["input"]) if "input" in e else ""
        errors.append({"field": field, "path": ".".join(loc), "msg": f"{field}: {e['msg']}{got}"})
    first = errors[0] if errors else {"field": "body", "msg": "invalid request"}
    return JSONResponse(status_code=422, content={"detail": first["msg"], "field": first["field"], "errors": errors})


_HEADERS = [
    (b"x-content-type-options", b"nosniff"),
    (b"referrer-policy", b"same-origin"),
    (b"content-security-policy", b"default-src 'self'; img-src 'self' data:; style-src 'self' 'unsafe-inline'; "
                                 b"frame-ancestors 'none'; form-action 'self'"),
]


class SecurityHeaders:
    """Adds the security headers to every response (a plain ASGI middleware: Starlette's
    `@app.middleware("http")` costs a task group and a stream per request)."""

    def __init__(self, app):
        self.app = app

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)

        async def send_with_headers(message):
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in message.get("headers", [])}
                message["headers"] = list(message.get("headers", [])) + [h for h in _HEADERS if h[0] not in names]
            await send(message)

        await self.app(scope, receive, send_with_headers)


def create_app(run_dir: str | Path, engine: Engine, settings: QueueSettings, ui_dir: Path = UI_DIR,
               docs: bool = False, limits: Limits = Limits()) -> FastAPI:
    # FastAPI's own docs routes answer anyone; ours (admin.docs_router) need a user
    app = FastAPI(title="libero-recover review", docs_url=None, redoc_url=None, openapi_url=None,
                  lifespan=_lifespan)
    app.state.review = ServerContext(Path(run_dir).resolve(), engine, settings)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(ReviewError, lambda _r, e: JSONResponse(status_code=e.status, content=e.body(),
                                                                          headers=e.headers()))
    app.state.limits = limits  # the server's protocol takes its header limits from here (server.py)
    app.add_middleware(RequestLimits, limits=limits)  # before routing, authentication and parsing
    app.add_middleware(SecurityHeaders)  # outermost: the limits' answers get the headers too
    # the routes of a reviewer's every item first: a request is matched against them in order
    for module in (queue, items, media, session, adjudication, admin):
        app.include_router(module.router)
    if docs:
        app.include_router(admin.docs_router)
    app.mount("/", StaticFiles(directory=ui_dir, html=True), name="ui")
    return app
