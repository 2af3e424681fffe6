"""Signing in and out, and who am I: POST /api/login, POST /api/logout, GET /api/me."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from pipeline.review import auth
from pipeline.review.deps import CtxDep, PrincipalDep, check_throttle, client_of
from pipeline.review.schemas import LoginIn

router = APIRouter(prefix="/api")


@router.post("/login")
async def login(request: Request, ctx: CtxDep):
    # JSON only: a cross-site form cannot send it without a CORS preflight (login CSRF).
    # The type is checked before the body is read, and no answer repeats the body: it holds
    # a personal token. Async to read the raw body; the database call runs in the threadpool.
    client = client_of(request)
    check_throttle(ctx, client)  # before the body is read: a throttled guess is not even parsed
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
    try:
        user, sid, csrf = await run_in_threadpool(auth.sign_in, ctx.engine, body.token)
    except auth.Unauthorized:
        ctx.throttle.failed(client)
        await run_in_threadpool(auth.record_failure, ctx.engine, client, "login")
        raise
    resp = JSONResponse({"user": user.name, "role": user.role, "csrf": csrf})
    resp.set_cookie(auth.COOKIE, sid, max_age=auth.SESSION_SECONDS, httponly=True, samesite="strict",
                    secure=request.url.scheme == "https", path="/")
    return resp


@router.post("/logout")
def logout(request: Request, _p: PrincipalDep, ctx: CtxDep):
    if request.cookies.get(auth.COOKIE):
        auth.sign_out(ctx.engine, request.cookies[auth.COOKIE])
    resp = JSONResponse({"ok": True})
    resp.delete_cookie(auth.COOKIE, path="/")
    return resp


@router.get("/me")
async def me(p: PrincipalDep, ctx: CtxDep):
    return {"user": p.user.name, "role": p.user.role, "csrf": p.csrf,
            "settings": {"required_reviews": ctx.settings.required_reviews,
                         "time_tolerance_s": ctx.settings.time_tolerance_s}}
