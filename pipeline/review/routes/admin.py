"""The queue's state for adjudicators and admins: GET /api/status; the OpenAPI docs, served
only with `docs=True` and only to people signed in."""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse

from pipeline.review import report, views
from pipeline.review.deps import AdjudicatorDep, CtxDep, ReadDb, UserDep

router = APIRouter(prefix="/api")


@router.get("/status")
def status(_user: AdjudicatorDep, s: ReadDb, ctx: CtxDep):
    with s.begin():
        return JSONResponse({"counts": views.counts(s), **report.summary(s, ctx.settings.time_tolerance_s)})


docs_router = APIRouter(prefix="/api", include_in_schema=False)


@docs_router.get("/openapi.json")
async def openapi(request: Request, _user: UserDep):
    return JSONResponse(request.app.openapi())


@docs_router.get("/docs")
async def api_docs(request: Request, _user: UserDep):
    from fastapi.openapi.docs import get_swagger_ui_html

    return get_swagger_ui_html(openapi_url="/api/openapi.json", title=request.app.title)
