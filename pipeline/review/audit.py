"""Append-only audit log of the review queue, and the per-item history view.

Inputs: the session of the write that changes something, the actor, before -> after.
Outputs: `events` rows (who, when, kind, before, after, the item's model/prompt version).
Invariants: events are only ever inserted, in the same transaction as the change they
describe (so a rolled-back change leaves no event); on SQLite, triggers abort any UPDATE
or DELETE of an event. Event kinds: enqueued, revision, leased, review, review_changed,
status, claimed, adjudicated, user_added, reviews_read (an adjudicator or admin
opened an item's reviews), user_deactivated, user_reactivated, login_failed (a token that
names nobody; the actor is `@<client address>`, the token is never stored).
"""

from __future__ import annotations

from datetime import datetime, timezone

from sqlalchemy import or_, select
from sqlalchemy.orm import Session

from pipeline.review.db import Event, Item


def record(
    s: Session,
    actor: str,
    kind: str,
    item: Item | None = None,
    before: dict | None = None,
    after: dict | None = None,
    detail: str = "",
) -> None:
    prop = item.proposal if item is not None else {}
    s.add(
        Event(
            actor=actor,
            kind=kind,
            item_id=item.id if item is not None else None,
            item_key=item.key if item is not None else None,
            before=before,
            after=after,
            model=prop.get("model") or prop.get("source"),
            prompt_name=prop.get("prompt_name"),
            prompt_hash=prop.get("prompt_hash"),
            detail=detail,
        )
    )


def iso(t: float | None) -> str | None:
    return None if t is None else datetime.fromtimestamp(t, timezone.utc).isoformat(timespec="seconds")


def history(s: Session, key_or_id: str | int) -> list[dict]:
    """Every event of an item (by id) or of all revisions of an episode key, oldest first."""
    if isinstance(key_or_id, int) or str(key_or_id).isdigit():
        item = s.get(Item, int(key_or_id))
        key = item.key if item is not None else None
    else:
        key = str(key_or_id)
    cond = Event.item_key == key if key is not None else Event.item_id == int(key_or_id)
    rows = s.scalars(select(Event).where(or_(cond)).order_by(Event.id)).all()
    return [
        {
            "id": e.id,
            "at": iso(e.at),
            "actor": e.actor,
            "kind": e.kind,
            "item_id": e.item_id,
            "before": e.before,
            "after": e.after,
            "model": e.model,
            "prompt_name": e.prompt_name,
            "prompt_hash": e.prompt_hash,
            "detail": e.detail,
        }
        for e in rows
    ]
