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
Whenever such a statement finds its condition false (a race, a held place, a repeat), nothing
has been written and the write falls back to the general path in `workflow`, which re-checks
everything in its own transaction and answers with the precise error. Audit events are
written in the same transaction as the change. The statements run on a DBAPI cursor
(`rawsql`: a tenth of the ORM's cost, inside the lock too) with the item's unchanging data
from `fastread`'s cache. With `wait=False` a write that would wait for the lock raises
`rawsql.Busy` having done nothing (the server then runs it in a thread that waits).
"""

from __future__ import annotations

from sqlalchemy import bindparam, case, delete, exists, func, insert, or_, select, update
from sqlalchemy.engine import Engine

from pipeline.review import fastread, workflow
from pipeline.review.db import COLLECTING, CONFLICT, FINAL, LEASED, PENDING, REVIEWED, Event, Item, Lease, Review, User
from pipeline.review.db import now, write_session
from pipeline.review.errors import NotFound, Stale
from pipeline.review.fields import agreement
from pipeline.review.rawsql import Busy, Stmt, param, reading, writing
from pipeline.vocab import Decision, Resolution

I, L, R, E = Item.__table__, Lease.__table__, Review.__table__, Event.__table__
_iid, _uid, _t = param("iid"), param("uid"), param("t")


def _others_leases():
    return (select(func.count()).select_from(L)
            .where(L.c.item_id == I.c.id, L.c.user_id != _uid, L.c.expires_at > _t).scalar_subquery())


def _insert(table, skip=("id",)) -> Stmt:
    return Stmt(insert(table).values({c.name: param(c.name) for c in table.c if c.name not in skip}))


_not_mine = ~exists().where(R.c.item_id == I.c.id, R.c.reviewer_id == _uid)
_not_read = ~exists().where(E.c.kind == workflow.READ_REVIEWS, E.c.actor == param("uname"), E.c.item_key == I.c.key)

# a first decision takes one of the K places: conditions as in workflow.submit_review
_TAKE = Stmt(
    update(I)
    .where(I.c.id == _iid, I.c.status.in_(COLLECTING), I.c.n_reviews < I.c.required_reviews, _not_mine, _not_read,
           or_(exists().where(L.c.item_id == I.c.id, L.c.user_id == _uid, L.c.expires_at > _t),
               I.c.n_reviews + _others_leases() < I.c.required_reviews))
    .values(n_reviews=I.c.n_reviews + 1, version=I.c.version + 1,
            status=case((I.c.n_reviews + 1 < I.c.required_reviews, REVIEWED), else_=I.c.status))
    .returning(I.c.n_reviews, I.c.required_reviews, I.c.status)
)
_ADD_REVIEW = _insert(R)
_DROP_LEASE = Stmt(delete(L).where(L.c.item_id == _iid, L.c.user_id == _uid))
_EVENT = _insert(E)
_VALUES = Stmt(select(R.c["values"]).where(R.c.item_id == _iid).order_by(R.c.id))
_CLOSE = {  # closing an item: conflict, or final with the agreed values
    CONFLICT: Stmt(update(I).where(I.c.id == _iid).values(
        version=I.c.version + 1, status=CONFLICT, agreed=param("agreed"), disputed=param("disputed"))),
    FINAL: Stmt(update(I).where(I.c.id == _iid).values(
        version=I.c.version + 1, status=FINAL, agreed=param("agreed"), disputed=param("disputed"),
        final=param("final"), resolution=Resolution.agreed, finalized_at=param("finalized_at"))),
}

# a new lease: conditions as in workflow.lease_item (no lease of mine yet, room left)
_HOLD = Stmt(
    update(I)
    .where(I.c.id == _iid, I.c.status.in_(COLLECTING), _not_mine, _not_read,
           ~exists().where(L.c.item_id == I.c.id, L.c.user_id == _uid, L.c.expires_at > _t),
           I.c.n_reviews + _others_leases() < I.c.required_reviews)
    .values(status=case((I.c.status == PENDING, LEASED), else_=I.c.status))
    .returning(I.c.id)
)
_ADD_LEASE = _insert(L)
# the queue's order (workflow.lease_next): fullest first, quarantined last
_HELD = Stmt(select(L.c.id).join(I, I.c.id == L.c.item_id)
             .where(L.c.user_id == _uid, L.c.expires_at > _t, I.c.status.in_(COLLECTING)).limit(1))
_all_leases = (select(func.count()).select_from(L).where(L.c.item_id == I.c.id, L.c.expires_at > _t)
               .scalar_subquery())
def _indexed_by(sql: str, table: str, index: str) -> str:
    out = sql.replace(f"\nFROM {table} \n", f"\nFROM {table} INDEXED BY {index} \n", 1)
    if out == sql:
        raise RuntimeError(f"no 'FROM {table}' to give the index {index} in: {sql[:120]}")
    return out


# on SQLite the search walks the partial index of the open queue, already in this order, and
# stops after `n` items (db.OPEN_QUEUE_INDEX; its WHERE is this one, with the statuses as
# literals); left to itself the planner took the status index and sorted every open item
_open = I.c.status.in_(bindparam("open", list(COLLECTING), expanding=True, literal_execute=True))
_CANDIDATES = Stmt(select(I.c.id, I.c.key, I.c.proposal)
                   .where(_open, I.c.n_reviews + _all_leases < I.c.required_reviews, _not_mine, _not_read)
                   .order_by(I.c.quarantined, I.c.n_reviews.desc(), I.c.id).limit(param("n")),
                   sqlite_edit=lambda sql: _indexed_by(sql, "items", "ix_items_open_queue"))


def _event(cur, actor: str, kind: str, item, before: dict | None, after: dict | None) -> None:
    prop = item.proposal or {}
    cur.run(_EVENT, at=now(), actor=actor, kind=kind, item_id=item.id, item_key=item.key, before=before, after=after,
            model=prop.get("model") or prop.get("source"), prompt_name=prop.get("prompt_name"),
            prompt_hash=prop.get("prompt_hash"), detail="")


def _close(cur, item: fastread.ItemInfo, before: str, cfg: workflow.QueueSettings, actor: str) -> str:
    """All K reviews are in (see workflow.close): final when every field agrees, else conflict."""
    values = [r.values for r in cur.all(_VALUES, iid=item.id)]
    hz = (item.context or {}).get("control_hz", cfg.control_hz)
    agreed, disputed = agreement(values, cfg.time_tolerance_s, hz)
    if disputed:
        status = CONFLICT
        cur.run(_CLOSE[CONFLICT], iid=item.id, agreed=agreed, disputed=disputed)
    else:
        status = FINAL
        cur.run(_CLOSE[FINAL], iid=item.id, agreed=agreed, disputed=disputed, final=agreed, finalized_at=now())
    _event(cur, actor, "status", item, {"status": before}, {"status": status, "disputed": disputed, "agreed": agreed})
    return status


def decide(engine: Engine, user: User, item_id: int, body: dict, cfg: workflow.QueueSettings,
           wait: bool = True) -> dict:
    """Store a decision (the API's answer: replayed, version, decision, values, state).
    `wait=False`: `rawsql.Busy` (nothing done) rather than wait for the writer lock."""
    with reading(engine) as cur:
        row = cur.first(fastread.MINE, iid=item_id, uid=user.id)  # the item's stamp and my review
    if row is None:
        raise NotFound(f"no item {item_id}")
    item = fastread.info_for(engine, item_id, (row.key, row.revision, row.created_at))
    first = row.review_id is None and bool(body.get("idempotency_key"))
    if first:
        decision, values, edited = workflow._values_for(item, body.get("decision"), body.get("fields"),
                                                        body.get("reason"), cfg)
        if int(body.get("version") or 0) != 0:
            raise Stale(f"your review of item {item.id} changed since you loaded it (version 0, you sent "
                        f"{body.get('version')})", current={"version": 0})
        with writing(engine, wait) as cur:
            t = now()
            took = cur.first(_TAKE, iid=item.id, uid=user.id, t=t, uname=user.name)
            if took is not None:
                reason = ((body.get("reason") or "").strip() or None) if decision == Decision.flag else None
                cur.run(_ADD_REVIEW, item_id=item.id, reviewer_id=user.id, decision=decision, values=values,
                        edited=edited, flag_reason=reason, idempotency_key=str(body["idempotency_key"]), version=1,
                        created_at=t, updated_at=t)
                cur.run(_DROP_LEASE, iid=item.id, uid=user.id)
                _event(cur, user.name, "review", item, None, {"decision": decision, "values": values,
                                                              "edited": edited, "reason": reason, "version": 1})
                status = took.status
                if took.n_reviews >= took.required_reviews:
                    status = _close(cur, item, took.status, cfg, user.name)
                return {"replayed": False, "version": 1, "decision": decision, "values": values,
                        "state": "open" if status in COLLECTING else "closed"}
    # a change of one's review, a repeat, or a condition that failed (nothing was written):
    # the general path, which re-checks everything in its own transaction
    if not wait:
        raise Busy("the general path waits for the writer lock")
    with write_session(engine) as s:
        r, replayed = workflow.submit_review(s, user, item_id, body, cfg)
        item = workflow.get_item(s, item_id)
        return {"replayed": replayed, "version": r.version, "decision": r.decision, "values": r.values,
                "state": "open" if item.status in COLLECTING else "closed"}


def next_item(engine: Engine, user: User, cfg: workflow.QueueSettings, candidates: int = 8,
              wait: bool = True) -> int | None:
    """Lease the user's next item (as workflow.lease_next); the search runs before the lock.
    `wait=False`: `rawsql.Busy` (nothing done) rather than wait for the writer lock."""
    t = now()
    params = {"uid": user.id, "t": t, "uname": user.name}
    with reading(engine) as cur:
        held = cur.first(_HELD, uid=user.id, t=t)
        rows = [] if held is not None else cur.all(_CANDIDATES, n=candidates, **params)
    if rows and not workflow.sweep_due(engine, t):
        with writing(engine, wait) as cur:
            for row in rows:
                if cur.first(_HOLD, iid=row.id, **params) is None:
                    continue  # taken meanwhile: the next candidate
                cur.run(_DROP_LEASE, iid=row.id, uid=user.id)  # an expired lease of mine, if any
                cur.run(_ADD_LEASE, item_id=row.id, user_id=user.id, expires_at=t + cfg.lease_seconds)
                _event(cur, user.name, "leased", row, None, None)
                return row.id
    # an item held already (renewed), the periodic sweep, or every candidate taken (nothing
    # was written): the general path
    if not wait:
        raise Busy("the general path waits for the writer lock")
    with write_session(engine) as s:
        item = workflow.lease_next(s, user, cfg)
        return item.id if item is not None else None
