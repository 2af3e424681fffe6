"""Conflicts, for adjudicators: GET /api/items/{id}/adjudication, POST .../claim,
POST .../adjudication, GET .../history (reviews are shown only through `blindness.open_reviews`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter
from fastapi.responses import JSONResponse

from pipeline.review import adjudication, audit, blindness, views, workflow
from pipeline.review.deps import AdjudicatorDep, CtxDep, ItemId, WriteDb, json_body
from pipeline.review.schemas import AdjudicationIn

router = APIRouter(prefix="/api/items")


@router.get("/{item_id}/adjudication")
def adjudication_page(item_id: ItemId, user: AdjudicatorDep, s: WriteDb):  # writes who read the reviews
    with s.begin():
        return JSONResponse(views.adjudication_view(s, blindness.open_reviews(s, user, item_id)))


@router.post("/{item_id}/claim")
def claim(item_id: ItemId, user: AdjudicatorDep, s: WriteDb):
    with s.begin():
        item = adjudication.claim(s, user, item_id)
        return {"item": item_id, "version": item.version, "status": item.status}


@router.post("/{item_id}/adjudication")
def adjudicate(item_id: ItemId, user: AdjudicatorDep, body: Annotated[AdjudicationIn, json_body(AdjudicationIn)],
               s: WriteDb, ctx: CtxDep):
    with s.begin():
        _adj, replayed = adjudication.adjudicate(s, user, item_id, body.payload(), ctx.settings)
        item = workflow.get_item(s, item_id)
        return JSONResponse({"replayed": replayed, "status": item.status, "final": item.final,
                             "resolution": item.resolution})


@router.get("/{item_id}/history")
def history(item_id: ItemId, user: AdjudicatorDep, s: WriteDb):  # spans every revision of the episode
    with s.begin():
        blindness.open_reviews(s, user, item_id, whole_episode=True)
        return {"item": item_id, "events": audit.history(s, item_id)}
