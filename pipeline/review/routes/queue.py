"""A reviewer's queue: GET /api/queue, GET /api/progress, POST /api/queue/next."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from pipeline.review import auth, views, workflow
from pipeline.review.deps import CtxDep, ReadDb, UserDep, WriteDb

router = APIRouter(prefix="/api")


@router.get("/queue")
def queue(user: UserDep, s: ReadDb, ctx: CtxDep):
    with s.begin():
        out = views.queue(s, user, auth.rank(user.role) >= auth.rank("adjudicator"))
        out["progress"] = views.progress(s, user, ctx.settings.time_tolerance_s, ctx.settings.control_hz)
        return JSONResponse(out)


@router.get("/progress")
def progress(user: UserDep, s: ReadDb, ctx: CtxDep):
    with s.begin():
        return JSONResponse(views.progress(s, user, ctx.settings.time_tolerance_s, ctx.settings.control_hz))


@router.post("/queue/next")
def next_item(user: UserDep, s: WriteDb, ctx: CtxDep):
    with s.begin():
        item = workflow.lease_next(s, user, ctx.settings)
        return JSONResponse({"item": item.id if item is not None else None})
