"""One item, as its reviewer sees it: GET /api/items/{id}, POST .../lease, POST .../review."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from pipeline.review import audit, views, workflow
from pipeline.review.deps import CtxDep, ItemId, ReadDb, UserDep, WriteDb, json_body
from pipeline.review.schemas import DecisionIn
from pipeline.vocab import COLLECTING

router = APIRouter(prefix="/api/items")


@router.get("/{item_id}")
def item(item_id: ItemId, user: UserDep, s: ReadDb):
    with s.begin():
        return JSONResponse(views.reviewer_view(s, item_id, user))


@router.post("/{item_id}/lease")
def lease(item_id: ItemId, user: UserDep, s: WriteDb, ctx: CtxDep):
    with s.begin():
        held = workflow.lease_item(s, user, workflow.get_item(s, item_id, lock=True), ctx.settings)
        return JSONResponse({"item": item_id, "expires_at": audit.iso(held.expires_at)})


@router.post("/{item_id}/review")
def review(item_id: ItemId, user: UserDep, body: Annotated[DecisionIn, json_body(DecisionIn)], s: WriteDb, ctx: CtxDep):
    with s.begin():
        r, replayed = workflow.submit_review(s, user, item_id, body.payload(), ctx.settings)
        state = "open" if workflow.get_item(s, item_id).status in COLLECTING else "closed"
        return JSONResponse({"replayed": replayed, "version": r.version, "decision": r.decision,
                             "values": r.values, "state": state})
