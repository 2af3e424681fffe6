"""The review server: JSON API, the web page (`review_ui/`) and the run's media.

Inputs: the run folder, a database engine, the queue settings.
Outputs: a FastAPI app. Routes (all JSON unless noted):
  POST /api/login {token} -> session cookie + csrf      POST /api/logout     GET /api/me
  GET  /api/queue (with `progress`)   GET /api/progress (done today, left, agreement so far)
  POST /api/queue/next       POST /api/items/{id}/lease
  GET  /api/items/{id}       POST /api/items/{id}/review (accept | revise | flag)
  GET  /api/items/{id}/evidence, /frames                GET  /api/items/{id}/history
  GET  /api/items/{id}/adjudication   POST .../claim    POST .../adjudication
  GET  /api/status           GET /media/<path under the run folder> (file)   GET / (the page)
Invariants: every route but login and the page needs a user (the OpenAPI docs too, served
only with `docs=True`); an item's reviews (adjudication, history) stay hidden while they are
being collected, and whoever has read them can no longer review that episode; writes
through the cookie need the CSRF header; errors are `{"detail", "field"?, "current"?}` with 401/403/404/409/422;
a request body that fails the schema is a 422 whose `field` names the bad field, and no
error repeats a secret (a token field, a whole body, a long value); sign-in takes JSON only
(415 otherwise, before the body is read). Decisions and queue/next write through
`fastwrite` (short under the SQLite writer lock).
"""

from __future__ import annotations

from contextlib import asynccontextmanager
from pathlib import Path

import anyio
from fastapi import Depends, FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from starlette.concurrency import run_in_threadpool
from sqlalchemy import select
from sqlalchemy.engine import Engine

from pipeline.records import Category, Decision, Level
from pipeline.review import adjudication, audit, auth, fastwrite, media, views, workflow
from pipeline.review.db import COLLECTING, Item, Review, read_session, write_session
from pipeline.review.errors import Forbidden, NotFound, ReviewError
from pipeline.review.workflow import QueueSettings

UI_DIR = Path(__file__).resolve().parents[2] / "review_ui"
# request threads per server process, for page loads and for the two writes of every item;
# measured with benchmarks/review_load.py (2, 8 and 16 were no better than 4 on 2 cores)
REQUEST_THREADS = 4
WRITE_THREADS = 4


class FieldsIn(BaseModel):
    """Edited fields; only the ones given count as edits."""

    model_config = ConfigDict(extra="forbid")
    fail_time_s: float | None = Field(default=None, ge=0)
    recovery_level: Level | None = None
    failure_category: Category | None = None
    recovery_action: str | None = Field(default=None, min_length=1, max_length=200)


class DecisionIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    decision: Decision
    fields: FieldsIn | None = None
    reason: str | None = Field(default=None, max_length=2000)
    version: int = Field(default=0, ge=0)
    idempotency_key: str = Field(min_length=1, max_length=100)


class AdjudicationIn(BaseModel):
    model_config = ConfigDict(extra="forbid")
    fields: FieldsIn = FieldsIn()
    rationale: str = Field(default="", max_length=4000)
    exclude: bool = False
    version: int = Field(ge=0)
    idempotency_key: str = Field(min_length=1, max_length=100)


class LoginIn(BaseModel):
    token: str = Field(min_length=1, max_length=200)


def _edits(f: FieldsIn | None) -> dict:
    return {} if f is None else f.model_dump(mode="json", exclude_unset=True)


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
               docs: bool = False) -> FastAPI:
    run_dir = Path(run_dir).resolve()

    @asynccontextmanager
    async def lifespan(_app):
        # few request threads per process: with dozens runnable, the one holding the SQLite
        # writer lock waits for the GIL behind the others and every writer queues longer
        # (requests beyond these wait, without CPU, in the event loop)
        anyio.to_thread.current_default_thread_limiter().total_tokens = REQUEST_THREADS
        yield

    limiters: dict = {}

    def writers() -> anyio.CapacityLimiter:
        # the two writes of every item (queue/next, decision) get threads of their own, so a
        # decision never waits for a thread behind page loads (made lazily: a limiter
        # belongs to the running event loop)
        if "w" not in limiters:
            limiters["w"] = anyio.CapacityLimiter(WRITE_THREADS)
        return limiters["w"]

    # FastAPI's own docs routes answer anyone; ours (below, with docs=True) need a user
    app = FastAPI(title="libero-recover review", docs_url=None, redoc_url=None, openapi_url=None, lifespan=lifespan)
    app.add_exception_handler(RequestValidationError, _validation_error)
    app.add_exception_handler(ReviewError, lambda _r, e: JSONResponse(status_code=e.status, content=e.body()))

    app.add_middleware(SecurityHeaders)

    async def who(request: Request) -> auth.Principal:
        # in the event loop, not a worker thread: a sub-millisecond indexed read (WAL readers
        # never wait for writers) costs less than the hop to a thread and back
        header = request.headers.get("authorization", "")
        bearer = header[7:].strip() if header.lower().startswith("bearer ") else None
        return auth.authenticate(engine, request.method, bearer, request.cookies.get(auth.COOKIE),
                                 request.headers.get(auth.CSRF_HEADER))

    async def adjudicator(p: auth.Principal = Depends(who)) -> auth.Principal:
        auth.require_role(p.user, "adjudicator")
        return p

    if docs:
        from fastapi.openapi.docs import get_swagger_ui_html

        @app.get("/api/openapi.json", include_in_schema=False)
        def openapi(_p: auth.Principal = Depends(who)):
            return JSONResponse(app.openapi())

        @app.get("/api/docs", include_in_schema=False)
        def api_docs(_p: auth.Principal = Depends(who)):
            return get_swagger_ui_html(openapi_url="/api/openapi.json", title=app.title)

    @app.post("/api/login")
    async def login(request: Request):
        # JSON only: a cross-site form cannot send it without a CORS preflight (login CSRF).
        # The type is checked before the body is parsed, and no answer repeats the body: it
        # holds a personal token
        if request.headers.get("content-type", "").split(";")[0].strip().lower() != "application/json":
            return JSONResponse(status_code=415, content={"detail": "send JSON: Content-Type: application/json",
                                                          "field": "content-type"})
        try:
            body = LoginIn.model_validate_json(await request.body())
        except ValidationError as e:
            field = next((str(p) for err in e.errors() for p in reversed(err["loc"])), "body")
            return JSONResponse(status_code=422, content={"detail": f"{field}: expected a JSON object "
                                                                    '{"token": "<your personal token>"}',
                                                          "field": field})
        user, sid, csrf = await run_in_threadpool(auth.sign_in, engine, body.token)
        resp = JSONResponse({"user": user.name, "role": user.role, "csrf": csrf})
        resp.set_cookie(auth.COOKIE, sid, max_age=auth.SESSION_SECONDS, httponly=True, samesite="strict",
                        secure=request.url.scheme == "https", path="/")
        return resp

    @app.post("/api/logout")
    def logout(request: Request, _p: auth.Principal = Depends(who)):
        if request.cookies.get(auth.COOKIE):
            auth.sign_out(engine, request.cookies[auth.COOKIE])
        resp = JSONResponse({"ok": True})
        resp.delete_cookie(auth.COOKIE, path="/")
        return resp

    @app.get("/api/me")
    def me(p: auth.Principal = Depends(who)):
        return {"user": p.user.name, "role": p.user.role, "csrf": p.csrf,
                "settings": {"required_reviews": settings.required_reviews,
                             "time_tolerance_s": settings.time_tolerance_s}}

    @app.get("/api/queue")
    def queue(p: auth.Principal = Depends(who)):
        with read_session(engine) as s:
            out = views.queue(s, p.user, auth.rank(p.user.role) >= auth.rank("adjudicator"))
            out["progress"] = views.progress(s, p.user, settings.time_tolerance_s, settings.control_hz)
            return JSONResponse(out)

    @app.get("/api/progress")
    def progress(p: auth.Principal = Depends(who)):
        with read_session(engine) as s:
            return JSONResponse(views.progress(s, p.user, settings.time_tolerance_s, settings.control_hz))

    @app.post("/api/queue/next")
    async def next_item(p: auth.Principal = Depends(who)):
        item = await anyio.to_thread.run_sync(fastwrite.next_item, engine, p.user, settings, limiter=writers())
        return JSONResponse({"item": item})

    @app.post("/api/items/{item_id}/lease")
    def lease(item_id: int, p: auth.Principal = Depends(who)):
        with write_session(engine) as s:
            lease = workflow.lease_item(s, p.user, workflow.get_item(s, item_id), settings)
            return {"item": item_id, "expires_at": audit.iso(lease.expires_at)}

    @app.get("/api/items/{item_id}")
    def item(item_id: int, p: auth.Principal = Depends(who)):
        with read_session(engine) as s:
            # JSONResponse directly: views are plain JSON already (skips FastAPI's re-encoding)
            return JSONResponse(views.reviewer_view(s, workflow.get_item(s, item_id), p.user))

    def _table(item_id: int, kind: str) -> Response:
        with read_session(engine) as s:
            ctx = workflow.get_item(s, item_id).context or {}
        path = media.safe_path(run_dir, ctx.get(kind) or "")
        if path is None:
            raise NotFound(f"item {item_id} has no {kind} table")
        body = media.evidence_json(path) if kind == "evidence" else media.frames_json(path)
        return Response(body, media_type="application/json", headers={"Cache-Control": "private, max-age=300"})

    @app.get("/api/items/{item_id}/evidence")
    def evidence(item_id: int, _p: auth.Principal = Depends(who)):
        return _table(item_id, "evidence")

    @app.get("/api/items/{item_id}/frames")
    def frames(item_id: int, _p: auth.Principal = Depends(who)):
        return _table(item_id, "frames")

    @app.post("/api/items/{item_id}/review")
    async def review(item_id: int, body: DecisionIn, p: auth.Principal = Depends(who)):
        payload = {**body.model_dump(mode="json", exclude={"fields"}), "fields": _edits(body.fields)}
        out = await anyio.to_thread.run_sync(fastwrite.decide, engine, p.user, item_id, payload, settings,
                                             limiter=writers())
        return JSONResponse(out)

    def _reviews_visible(s, p: auth.Principal, item_id: int, whole_episode: bool = False):
        # blindness: nobody reads an item's reviews while they are being collected, nobody
        # reads the others' decisions on an item they reviewed, and whoever reads them is
        # recorded so that they can no longer review that episode (workflow.note_reviews_read)
        item = workflow.get_item(s, item_id)
        keys = [item.key] if whole_episode else []
        if item.status in COLLECTING or (keys and s.scalar(select(Item.id).where(Item.key.in_(keys),
                                                                                   Item.status.in_(COLLECTING)))):
            raise Forbidden(f"item {item_id}: reviews are still being collected; they stay hidden until then")
        if auth.rank(p.user.role) < auth.rank("admin") or not whole_episode:
            if s.scalar(select(Review.id).where(Review.item_id == item_id, Review.reviewer_id == p.user.id)):
                raise Forbidden(f"you reviewed item {item_id}; its other decisions stay hidden from you")
        workflow.note_reviews_read(s, p.user, item)
        return item

    @app.get("/api/items/{item_id}/adjudication")
    def adjudication_page(item_id: int, p: auth.Principal = Depends(adjudicator)):
        with write_session(engine) as s:
            return JSONResponse(views.adjudication_view(s, _reviews_visible(s, p, item_id)))

    @app.post("/api/items/{item_id}/claim")
    def claim(item_id: int, p: auth.Principal = Depends(adjudicator)):
        with write_session(engine) as s:
            item = adjudication.claim(s, p.user, item_id)
            return {"item": item_id, "version": item.version, "status": item.status}

    @app.post("/api/items/{item_id}/adjudication")
    def adjudicate(item_id: int, body: AdjudicationIn, p: auth.Principal = Depends(adjudicator)):
        payload = {**body.model_dump(mode="json", exclude={"fields"}), "fields": _edits(body.fields)}
        with write_session(engine) as s:
            adj, replayed = adjudication.adjudicate(s, p.user, item_id, payload, settings)
            item = workflow.get_item(s, item_id)
            return {"replayed": replayed, "status": item.status, "final": item.final, "resolution": item.resolution}

    @app.get("/api/items/{item_id}/history")
    def history(item_id: int, p: auth.Principal = Depends(adjudicator)):
        with write_session(engine) as s:  # the history spans every revision of the episode
            _reviews_visible(s, p, item_id, whole_episode=True)
            return {"item": item_id, "events": audit.history(s, item_id)}

    @app.get("/api/status")
    def status(_p: auth.Principal = Depends(adjudicator)):
        from pipeline.review import report

        with read_session(engine) as s:
            return {"counts": views.counts(s), **report.summary(s, settings.time_tolerance_s)}

    @app.get("/media/{rel:path}")
    def media_file(rel: str, _p: auth.Principal = Depends(who)):
        path = media.safe_path(run_dir, rel)
        if path is None:
            raise NotFound("no such file")
        return FileResponse(path, headers={"Cache-Control": "private, max-age=3600"})

    app.mount("/", StaticFiles(directory=ui_dir, html=True), name="ui")
    return app
