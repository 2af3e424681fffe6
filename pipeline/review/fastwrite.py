"""The two writes every reviewer makes per item, kept short under the writer lock.

Inputs: the engine, the acting user, the request body, the queue settings.
Outputs: the same results as `workflow.submit_review` / `workflow.lease_next`.
Why: SQLite takes one writer at a time, so the time a write holds the lock bounds the whole
team's throughput (20 reviewers back to back queue on it). Everything that can be checked
before the lock is: the item, the reviewer's own review, validation of the values (a read
transaction, no lock). Under the lock a first decision is then a handful of prebuilt Core
statements whose WHERE clauses re-check every invariant atomically:
- the review count rises only while `n_reviews < required_reviews` and the item collects;
- a reviewer without a lease may not take a place others hold;
- nobody who has read the episode's reviews, and nobody twice.
Whenever such a statement finds its condition false (a race, a held place, a repeat), the
write falls back, in the same locked transaction, to the general path in `workflow`, which
answers with the precise error. Audit events are written in the same transaction as before.
"""

from __future__ import annotations

from sqlalchemy import bindparam, case, delete, exists, func, insert, or_, select, update
from sqlalchemy.engine import Engine

from pipeline.review import workflow
from pipeline.review.db import COLLECTING, CONFLICT, FINAL, LEASED, PENDING, REVIEWED, Event, Item, Lease, Review, User
from pipeline.review.db import now, read_session, write_session
from pipeline.review.errors import Stale
from pipeline.review.fields import agreement
from pipeline.vocab import Decision, Resolution

I, L, R, E = Item.__table__, Lease.__table__, Review.__table__, Event.__table__
_iid, _uid, _t = bindparam("iid"), bindparam("uid"), bindparam("t")


def _others_leases():
    return (select(func.count()).select_from(L)
            .where(L.c.item_id == I.c.id, L.c.user_id != _uid, L.c.expires_at > _t).scalar_subquery())


_not_mine = ~exists().where(R.c.item_id == I.c.id, R.c.reviewer_id == _uid)
_not_read = ~exists().where(E.c.kind == workflow.READ_REVIEWS, E.c.actor == bindparam("uname"), E.c.item_key == I.c.key)

# a first decision takes one of the K places: conditions as in workflow.submit_review
_TAKE = (
    update(I)
    .where(I.c.id == _iid, I.c.status.in_(COLLECTING), I.c.n_reviews < I.c.required_reviews, _not_mine, _not_read,
           or_(exists().where(L.c.item_id == I.c.id, L.c.user_id == _uid, L.c.expires_at > _t),
               I.c.n_reviews + _others_leases() < I.c.required_reviews))
    .values(n_reviews=I.c.n_reviews + 1, version=I.c.version + 1,
            status=case((I.c.n_reviews + 1 < I.c.required_reviews, REVIEWED), else_=I.c.status))
    .returning(I.c.n_reviews, I.c.required_reviews, I.c.status)
)
_ADD_REVIEW = insert(R)
_DROP_LEASE = delete(L).where(L.c.item_id == _iid, L.c.user_id == _uid)
_EVENT = insert(E)
_VALUES = select(R.c["values"]).where(R.c.item_id == _iid).order_by(R.c.id)
_CLOSE = update(I).where(I.c.id == _iid).values(version=I.c.version + 1)

# a new lease: conditions as in workflow.lease_item (no lease of mine yet, room left)
_HOLD = (
    update(I)
    .where(I.c.id == _iid, I.c.status.in_(COLLECTING), _not_mine, _not_read,
           ~exists().where(L.c.item_id == I.c.id, L.c.user_id == _uid, L.c.expires_at > _t),
           I.c.n_reviews + _others_leases() < I.c.required_reviews)
    .values(status=case((I.c.status == PENDING, LEASED), else_=I.c.status))
    .returning(I.c.id)
)
_ADD_LEASE = insert(L)
# the queue's order (workflow.lease_next): fullest first, quarantined last; prebuilt, since
# building this statement anew cost more than running it
_HELD = (select(L.c.id).join(I, I.c.id == L.c.item_id)
         .where(L.c.user_id == _uid, L.c.expires_at > _t, I.c.status.in_(COLLECTING)).limit(1))
_all_leases = (select(func.count()).select_from(L).where(L.c.item_id == I.c.id, L.c.expires_at > _t)
               .scalar_subquery())
_CANDIDATES = (select(I.c.id, I.c.key, I.c.proposal)
               .where(I.c.status.in_(COLLECTING), I.c.n_reviews + _all_leases < I.c.required_reviews, _not_mine,
                      _not_read)
               .order_by(I.c.quarantined, I.c.n_reviews.desc(), I.c.id).limit(bindparam("n")))


def _event(s, actor: str, kind: str, item, before: dict | None, after: dict | None) -> None:
    prop = item.proposal or {}
    s.execute(_EVENT, {"at": now(), "actor": actor, "kind": kind, "item_id": item.id, "item_key": item.key,
                       "before": before, "after": after, "model": prop.get("model") or prop.get("source"),
                       "prompt_name": prop.get("prompt_name"), "prompt_hash": prop.get("prompt_hash"), "detail": ""})


def _close(s, item: Item, before: str, cfg: workflow.QueueSettings, actor: str) -> str:
    """All K reviews are in (see workflow.close): final when every field agrees, else conflict."""
    values = s.scalars(_VALUES, {"iid": item.id}).all()
    hz = (item.context or {}).get("control_hz", cfg.control_hz)
    agreed, disputed = agreement(values, cfg.time_tolerance_s, hz)
    change: dict = {"agreed": agreed, "disputed": disputed}
    if disputed:
        change["status"] = CONFLICT
    else:
        change.update(status=FINAL, final=agreed, resolution=Resolution.agreed, finalized_at=now())
    s.execute(_CLOSE.values(**change), {"iid": item.id})
    _event(s, actor, "status", item, {"status": before},
           {"status": change["status"], "disputed": disputed, "agreed": agreed})
    return change["status"]


def decide(engine: Engine, user: User, item_id: int, body: dict, cfg: workflow.QueueSettings) -> dict:
    """Store a decision (the API's answer: replayed, version, decision, values, state)."""
    with read_session(engine) as s:
        item = workflow.get_item(s, item_id)
        mine = s.scalar(select(Review.id).where(Review.item_id == item.id, Review.reviewer_id == user.id))
        first = mine is None and bool(body.get("idempotency_key"))
        if first:
            decision, values, edited = workflow._values_for(item, body.get("decision"), body.get("fields"),
                                                            body.get("reason"), cfg)
            if int(body.get("version") or 0) != 0:
                raise Stale(f"your review of item {item.id} changed since you loaded it (version 0, you sent "
                            f"{body.get('version')})", current={"version": 0})
    with write_session(engine) as s:
        if first:
            t = now()
            took = s.execute(_TAKE, {"iid": item.id, "uid": user.id, "t": t, "uname": user.name}).first()
            if took is not None:
                reason = ((body.get("reason") or "").strip() or None) if decision == Decision.flag else None
                key = str(body["idempotency_key"])
                s.execute(_ADD_REVIEW, {"item_id": item.id, "reviewer_id": user.id, "decision": decision,
                                        "values": values, "edited": edited, "flag_reason": reason,
                                        "idempotency_key": key, "version": 1, "created_at": t, "updated_at": t})
                s.execute(_DROP_LEASE, {"iid": item.id, "uid": user.id})
                _event(s, user.name, "review", item, None, {"decision": decision, "values": values,
                                                            "edited": edited, "reason": reason, "version": 1})
                status = took.status
                if took.n_reviews >= took.required_reviews:
                    status = _close(s, item, took.status, cfg, user.name)
                return {"replayed": False, "version": 1, "decision": decision, "values": values,
                        "state": "open" if status in COLLECTING else "closed"}
        # a change of one's review, a repeat, or a condition that failed: the general path
        r, replayed = workflow.submit_review(s, user, item_id, body, cfg)
        item = workflow.get_item(s, item_id)
        return {"replayed": replayed, "version": r.version, "decision": r.decision, "values": r.values,
                "state": "open" if item.status in COLLECTING else "closed"}


def next_item(engine: Engine, user: User, cfg: workflow.QueueSettings, candidates: int = 8) -> int | None:
    """Lease the user's next item (as workflow.lease_next); the search runs before the lock."""
    t = now()
    with read_session(engine) as s:
        params = {"uid": user.id, "t": t, "uname": user.name, "n": candidates}
        held = s.execute(_HELD, params).first()
        rows = [] if held is not None else s.execute(_CANDIDATES, params).all()
    with write_session(engine) as s:
        if rows and not workflow.sweep_due(s, t):
            for row in rows:
                if s.execute(_HOLD, {"iid": row.id, "uid": user.id, "t": t, "uname": user.name}).first() is None:
                    continue  # taken meanwhile: the next candidate
                s.execute(_DROP_LEASE, {"iid": row.id, "uid": user.id})  # an expired lease of mine, if any
                s.execute(_ADD_LEASE, {"item_id": row.id, "user_id": user.id, "expires_at": t + cfg.lease_seconds})
                _event(s, user.name, "leased", row, None, None)
                return row.id
        # an item held already (renewed), the periodic sweep, or every candidate taken
        item = workflow.lease_next(s, user, cfg)
        return item.id if item is not None else None

