"""What every route depends on: the server's context, the acting person, a database session.

Inputs: the request (its bearer token or session cookie and CSRF header) and the app's state.
Outputs: FastAPI dependencies, used as annotated parameters (`UserDep`, `WriteDb`, ...).
Invariants: every dependency that touches the database is a plain `def`, so FastAPI runs it
in its threadpool, never on the event loop; a route lists the person first, so nobody
unauthenticated opens a transaction; a request body is read and parsed only after the caller
is known (`json_body`), and only JSON (a 422 otherwise); a write route runs its work in
`with s.begin():` on its `WriteDb`, so it is committed (or rolled back on any error) in the
route's own thread, before the response is sent: an acknowledged write is stored.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

from fastapi import Depends, Path as PathParam, Request
from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, ValidationError
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session

from pipeline.review import auth
from pipeline.review.db import User, read_session, writer
from pipeline.review.errors import TooManyRequests
from pipeline.review.media import VideoAllowlist
from pipeline.review.throttle import FailureThrottle
from pipeline.review.workflow import QueueSettings


@dataclass(frozen=True)
class ServerContext:
    run_dir: Path
    engine: Engine
    settings: QueueSettings
    videos: VideoAllowlist = field(default_factory=VideoAllowlist)
    throttle: FailureThrottle = field(default_factory=FailureThrottle)


async def get_ctx(request: Request) -> ServerContext:  # no I/O: no threadpool hop
    return request.app.state.review


CtxDep = Annotated[ServerContext, Depends(get_ctx)]


def client_of(request: Request) -> str:
    return request.client.host if request.client else "unknown"


def check_throttle(ctx: ServerContext, client: str) -> None:
    """429 while `client` has failed to sign in too often (before any credential is checked)."""
    wait = ctx.throttle.retry_after(client)
    if wait:
        raise TooManyRequests(f"too many failed sign-ins from {client}; retry in {wait} s", wait)


def current_principal(request: Request, ctx: CtxDep) -> auth.Principal:
    header = request.headers.get("authorization", "")
    bearer = header[7:].strip() if header.lower().startswith("bearer ") else None
    cookie = request.cookies.get(auth.COOKIE)
    client = client_of(request)
    if bearer or cookie:
        check_throttle(ctx, client)
    try:
        return auth.authenticate(ctx.engine, request.method, bearer, cookie, request.headers.get(auth.CSRF_HEADER))
    except auth.Unauthorized:
        if bearer or cookie:  # a guess costs; no credentials at all ("sign in first") does not
            ctx.throttle.failed(client)
        if bearer:  # an expired session cookie is routine, a wrong token is not
            auth.record_failure(ctx.engine, client, "bearer token")
        raise


PrincipalDep = Annotated[auth.Principal, Depends(current_principal)]


async def current_user(p: PrincipalDep) -> User:
    return p.user


async def current_adjudicator(p: PrincipalDep) -> User:
    auth.require_role(p.user, "adjudicator")
    return p.user


UserDep = Annotated[User, Depends(current_user)]
AdjudicatorDep = Annotated[User, Depends(current_adjudicator)]


def read_db(ctx: CtxDep) -> Iterator[Session]:
    with read_session(ctx.engine) as s:
        yield s


def write_db(ctx: CtxDep) -> Iterator[Session]:
    # no transaction here: the route runs `with s.begin():` itself, so the transaction (and
    # SQLite's write lock) begins and ends inside one threadpool call, never held across the
    # hops back to the event loop and into another thread for the dependency's exit
    with writer(ctx.engine) as s:
        yield s


ReadDb = Annotated[Session, Depends(read_db, scope="function")]
WriteDb = Annotated[Session, Depends(write_db, scope="function")]


# item ids are the database's 32-bit integers: anything else is a 422, never a database error
ItemId = Annotated[int, PathParam(ge=1, le=2**31 - 1)]


def json_body(model: type[BaseModel]):
    """A dependency giving the request's JSON body as `model`, read and parsed only after the
    caller is authenticated (it depends on `current_user`, which runs first). Errors are
    FastAPI's 422s (the `field` named, `api._validation_error`); JSON nested too deep for the
    parser is one of them."""

    async def parse(request: Request, _user: UserDep) -> BaseModel:
        kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
        if kind != "application/json":
            raise RequestValidationError([{"type": "content_type", "loc": ("body",), "input": None,
                                           "msg": "send JSON (Content-Type: application/json)"}])
        try:
            return model.model_validate_json(await request.body())
        except ValidationError as e:
            raise RequestValidationError([{**err, "loc": ("body", *err["loc"])} for err in e.errors()]) from None

    return Depends(parse)
