"""What each person is shown: the reviewer's item, the adjudicator's item, the queue.

Inputs: a read session, the item, the viewing user.
Outputs: JSON-ready dicts.
Invariants: the reviewer view never contains another reviewer's decision, count or the
item's agreement state (only "open" or "closed"); the adjudication view, for someone who
did not review the item, shows every reviewer's values beside the model's, per field.
"""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from pipeline.review.audit import iso
from pipeline.review.db import ADJUDICATING, COLLECTING, CONFLICT, Item, Lease, Review, User, now
from pipeline.review.fields import CATEGORIES, FIELDS, LEVELS


def _media(ctx: dict) -> dict:
    def url(rel: str | None) -> str | None:
        return f"/media/{rel}" if rel else None

    return {
        "videos": {cam: url(p) for cam, p in (ctx.get("videos") or {}).items()},
        "has_frames": bool(ctx.get("frames")),
        "has_evidence": bool(ctx.get("evidence")),
        "fps": ctx.get("fps"),
        "control_hz": ctx.get("control_hz", 20),
        "duration_s": ctx.get("duration_s"),
        "phases": ctx.get("phases"),
        "events": ctx.get("events") or [],
    }


def _base(item: Item) -> dict:
    return {
        "id": item.id,
        "key": item.key,
        "revision": item.revision,
        "suite": item.suite,
        "task": item.task,
        "episode_id": item.episode_id,
        "instruction": item.instruction,
        "quarantined": item.quarantined,
        "quarantine_reason": item.quarantine_reason,
        "quarantine_detail": item.quarantine_detail,
        "proposal": item.proposal,  # a suggestion, shown with its model and prompt version
        "media": _media(item.context or {}),
        "choices": {"recovery_level": LEVELS, "failure_category": CATEGORIES, "fields": list(FIELDS)},
    }


def reviewer_view(s: Session, item: Item, user: User) -> dict:
    mine = s.scalar(select(Review).where(Review.item_id == item.id, Review.reviewer_id == user.id))
    lease = s.scalar(select(Lease).where(Lease.item_id == item.id, Lease.user_id == user.id))
    t = now()
    out = _base(item)
    out["state"] = "open" if item.status in COLLECTING else "closed"
    out["lease_expires_at"] = iso(lease.expires_at) if lease is not None and lease.expires_at > t else None
    out["my_review"] = None if mine is None else {
        "decision": mine.decision, "values": mine.values, "edited": mine.edited,
        "reason": mine.flag_reason, "version": mine.version, "at": iso(mine.updated_at),
    }
    out["version"] = mine.version if mine is not None else 0
    return out


def adjudication_view(s: Session, item: Item) -> dict:
    rows = s.execute(
        select(Review, User.name).join(User, User.id == Review.reviewer_id)
        .where(Review.item_id == item.id).order_by(Review.id)
    ).all()
    out = _base(item)
    adjudicator = s.get(User, item.adjudicator_id) if item.adjudicator_id else None
    out.update({
        "status": item.status,
        "version": item.version,
        "disputed": item.disputed or [],
        "agreed": item.agreed or {},
        "final": item.final,
        "resolution": item.resolution,
        "adjudicator": adjudicator.name if adjudicator else None,
        "reviews": [
            {"reviewer": name, "decision": r.decision, "values": r.values, "edited": r.edited,
             "reason": r.flag_reason, "at": iso(r.updated_at)}
            for r, name in rows
        ],
    })
    return out


def _row(item: Item) -> dict:
    return {"id": item.id, "key": item.key, "revision": item.revision, "instruction": item.instruction,
            "quarantined": item.quarantined, "quarantine_reason": item.quarantine_reason}


def queue(s: Session, user: User, can_adjudicate: bool, limit: int = 200) -> dict:
    """The queue page of one user: held items, items open to them, their past decisions, conflicts."""
    t = now()
    held = s.scalars(
        select(Item).join(Lease, Lease.item_id == Item.id)
        .where(Lease.user_id == user.id, Lease.expires_at > t, Item.status.in_(COLLECTING)).order_by(Item.id)
    ).all()
    mine = select(Review.item_id).where(Review.reviewer_id == user.id)
    leases = select(func.count(Lease.id)).where(Lease.item_id == Item.id, Lease.expires_at > t).scalar_subquery()
    open_q = (select(Item).where(Item.status.in_(COLLECTING), Item.n_reviews + leases < Item.required_reviews,
                                 Item.id.not_in(mine), Item.id.not_in([i.id for i in held])))
    n_open = s.scalar(select(func.count()).select_from(open_q.subquery())) or 0
    available = s.scalars(open_q.order_by(Item.quarantined, Item.n_reviews.desc(), Item.id).limit(limit)).all()
    done = s.execute(
        select(Item, Review).join(Review, Review.item_id == Item.id)
        .where(Review.reviewer_id == user.id).order_by(Review.updated_at.desc()).limit(limit)
    ).all()
    out = {
        "user": user.name,
        "role": user.role,
        "held": [_row(i) for i in held],
        "available": [_row(i) for i in available],
        "available_total": n_open,
        "reviewed": [{**_row(i), "decision": r.decision, "state": "open" if i.status in COLLECTING else "closed"}
                     for i, r in done],
        "conflicts": [],
    }
    if can_adjudicate:
        conflicts = s.scalars(
            select(Item).where(Item.status.in_((CONFLICT, ADJUDICATING)), Item.id.not_in(mine)).order_by(Item.id)
        ).all()
        out["conflicts"] = [
            {**_row(i), "disputed": i.disputed or [], "status": i.status,
             "claimed_by_other": i.status == ADJUDICATING and i.adjudicator_id != user.id
             and (i.adjudication_lease_until or 0) > t}
            for i in conflicts
        ]
    return out


def counts(s: Session) -> dict:
    rows = s.execute(select(Item.status, Item.quarantined, func.count()).group_by(Item.status, Item.quarantined)).all()
    out: dict = {"total": 0, "quarantined": 0, "by_status": {}}
    for status, quarantined, n in rows:
        out["by_status"][status] = out["by_status"].get(status, 0) + n
        out["total"] += n
        out["quarantined"] += n if quarantined else 0
    return out
