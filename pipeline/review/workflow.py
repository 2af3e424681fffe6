"""The reviewing half of the state machine: leases, decisions, and closing an item.

pending -> leased -> reviewed (k of K) -> agreed (-> final) | conflict
Inputs: a write session, the acting user, the item, the decision body.
Invariants:
- never more than K reviews: the review count rises by a conditional UPDATE
  (`n_reviews < required_reviews`), and the (item, reviewer) unique constraint backs it;
- leases are advisory and expire; an expired lease holds nothing; a person holds at most
  `max_leases` items at once, and renewing a lease never extends it past `lease_max_s` after
  it was taken (an expired one is taken afresh, subject to room like anyone's);
- a decision carries the version of the reviewer's own review it replaces (0 = none):
  anything else is stale (409); the same decision again (same idempotency key, or the
  same content after normalization, e.g. `fail_time_s: "5"` when it is 5) is answered
  with the stored review and changes nothing (no new version, no audit event);
- an edit is a field whose value differs from the model's proposal: a revision that ends
  up with the model's own values (its time on the control grid) is stored as an accept;
- once K reviews exist the item leaves the queue: final when every field agrees,
  otherwise conflict with the disputed fields named (see `fields.agreement`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from sqlalchemy import Integer, and_, bindparam, delete, exists, func, select, update
from sqlalchemy.engine import Engine
from sqlalchemy.orm import Session, aliased
from sqlalchemy.orm.attributes import set_committed_value

from pipeline.review import audit, blindness
from pipeline.review.db import IS_COLLECTING, Item, Lease, Review, User, now
from pipeline.review.errors import Invalid, NotFound, Stale
from pipeline.review.fields import FieldError, agreement, edited_fields, resolve
from pipeline.vocab import COLLECTING, Decision, ItemStatus, Resolution

DECISIONS = tuple(d.value for d in Decision)


@dataclass(frozen=True)
class QueueSettings:
    required_reviews: int = 2
    time_tolerance_s: float = 0.5
    lease_seconds: int = 900
    control_hz: int = 20
    max_leases: int = 3  # items one person may hold at once (the page works on one)
    lease_max_s: int = 3600  # a lease is never renewed past this long after it was taken


# the item under its row lock, read afresh even if the session holds it (built once: `Session.get`
# with a lock builds its statement on every call)
_LOCKED_ITEM = (select(Item).where(Item.id == bindparam("item_id")).with_for_update()
                .execution_options(populate_existing=True))


def get_item(s: Session, item_id: int, lock: bool = False) -> Item:
    """The item (404 if none); `lock`: with its row lock (FOR UPDATE on PostgreSQL, where two
    transactions may otherwise check the same item at once; SQLite's writer is alone anyway)."""
    item = s.scalars(_LOCKED_ITEM, {"item_id": item_id}).first() if lock else s.get(Item, item_id)
    if item is None:
        raise NotFound(f"no item {item_id}")
    return item


def _active_leases(s: Session, item_id: int, t: float) -> int:
    return s.scalar(select(func.count(Lease.id)).where(Lease.item_id == item_id, Lease.expires_at > t)) or 0


def refresh_status(s: Session, item: Item, t: float | None = None, leased: bool | None = None) -> None:
    """Recompute the status of an item that is still collecting reviews (`leased`: whether a
    live lease on it is known to exist; None: count them)."""
    if item.status not in COLLECTING:
        return
    if item.n_reviews:
        item.status = ItemStatus.reviewed
        return
    if leased is None:
        leased = _active_leases(s, item.id, now() if t is None else t) > 0
    item.status = ItemStatus.leased if leased else ItemStatus.pending


def expire(s: Session, t: float | None = None) -> int:
    """Drop expired leases and adjudication claims; return how many were dropped."""
    t = now() if t is None else t
    # the items first, in id order (row locks on PostgreSQL; a writer holding one item never
    # waits for another, so this order cannot deadlock), then their leases
    stale = s.scalars(
        select(Item).where(Item.id.in_(select(Lease.item_id).where(Lease.expires_at <= t))
                           | ((Item.status == ItemStatus.adjudicating) & (Item.adjudication_lease_until <= t)))
        .order_by(Item.id).with_for_update()
    ).all()
    if not stale:
        return 0
    dropped = s.execute(delete(Lease).where(Lease.expires_at <= t, Lease.item_id.in_([i.id for i in stale]))).rowcount
    for item in stale:
        if item.status == ItemStatus.adjudicating and (item.adjudication_lease_until or 0) <= t:
            item.status, item.adjudicator_id, item.adjudication_lease_until = ItemStatus.conflict, None, None
            item.version += 1
            dropped += 1
        else:
            refresh_status(s, item, t)
    return dropped


def _reviewed_by(user_id: int):
    return exists().where(and_(Review.item_id == Item.id, Review.reviewer_id == user_id))


class Standing(NamedTuple):
    """What the rules ask about one person and one item, read in one statement (`standing`)."""
    review: Review | None  # their review of it
    lease: Lease | None  # their lease on it, live or expired
    read: bool  # they read the reviews of its episode (`blindness`)
    others: int  # live leases of other people on it
    held: int  # live leases they hold, on any item


# The hot statements are built once, their values bound per call (`:user_id`, `:actor` (the
# user's name), `:t` (now), `:item_id`, ...): building a statement and its cache key cost
# more than SQLAlchemy's compiled-statement cache saves.
_UID, _T, _ACTOR = bindparam("user_id"), bindparam("t"), bindparam("actor")


def _standing_stmt():
    mine = aliased(Lease)  # the counts below are over all leases, not this joined row
    others = (select(func.count(Lease.id)).where(Lease.item_id == Item.id, Lease.expires_at > _T,
                                                 Lease.user_id != _UID).correlate(Item).scalar_subquery())
    held = select(func.count(Lease.id)).where(Lease.user_id == _UID, Lease.expires_at > _T).correlate(None).scalar_subquery()
    return (select(Review, mine, blindness.has_read(_ACTOR), others, held).select_from(Item)
            .outerjoin(Review, and_(Review.item_id == Item.id, Review.reviewer_id == _UID))
            .outerjoin(mine, and_(mine.item_id == Item.id, mine.user_id == _UID))
            .where(Item.id == bindparam("item_id")))


_STANDING = _standing_stmt()


def _who(user: User, t: float) -> dict:
    return {"user_id": user.id, "actor": user.name, "t": t}


def standing(s: Session, user: User, item_id: int, t: float) -> Standing:
    """`Standing` of `user` on item `item_id` at time `t` (one row: the review and the lease
    are unique per (item, person))."""
    row = s.execute(_STANDING, {**_who(user, t), "item_id": item_id}).one()
    return Standing(row[0], row[1], bool(row[2]), row[3] or 0, row[4] or 0)


def lease_item(s: Session, user: User, item: Item, cfg: QueueSettings) -> Lease:
    """Hold `item` for `user` for the lease time (renewing a lease they hold)."""
    t = now()
    if item.status not in COLLECTING:
        raise Stale(f"item {item.id} is {item.status}, not open for review", current={"status": item.status})
    st = standing(s, user, item.id, t)
    if st.review is not None:
        raise Stale(f"you already reviewed item {item.id}")
    blindness.refuse_write(s, user, item, read=st.read)
    lease = st.lease
    if lease is None or lease.expires_at <= t:
        if item.n_reviews + st.others >= item.required_reviews:
            raise Stale(f"item {item.id} already has {item.required_reviews} reviewers")
        if st.held >= cfg.max_leases:
            raise Stale(f"you already hold {st.held} items (at most {cfg.max_leases}); decide one of them first")
        if lease is None:
            lease = Lease(item_id=item.id, user_id=user.id)
            s.add(lease)
        lease.taken_at = t
        audit.record(s, user.name, "leased", item)
    lease.expires_at = min(t + cfg.lease_seconds, lease.taken_at + cfg.lease_max_s)
    refresh_status(s, item, t, leased=True)  # written with the lease, at the flush
    return lease


_last_sweep: dict[str, float] = {}  # database URL -> time of the last sweep
SWEEP_EVERY_S = 5.0
QUEUE_PAGE = 64  # open items lease_next examines at a time


def _sweep_key(s: Session | Engine) -> str:
    return (s.get_bind() if isinstance(s, Session) else s).url.render_as_string(hide_password=True)


def sweep_due(s: Session | Engine, t: float) -> bool:
    return t - _last_sweep.get(_sweep_key(s), 0.0) >= SWEEP_EVERY_S


_ORDER = (Item.quarantined, Item.n_reviews.desc(), Item.id)
# the items the user holds, found from their leases (a handful), not by walking the items
_HELD_ITEM = (
    select(Item)
    .where(Item.id.in_(select(Lease.item_id).where(Lease.user_id == _UID, Lease.expires_at > _T)),
           Item.status.in_(COLLECTING), ~_reviewed_by(_UID), ~blindness.has_read(_ACTOR))
    .order_by(Item.id).limit(1).with_for_update(of=Item)
)
# a page of the open items in queue order: the conditions below (correlated subqueries) then
# run on a page, not on every open item of a long queue. The page is the first rows of the
# partial index of open items (`db.IS_COLLECTING`, `ix_items_queue_open`), so neither a long
# queue nor the items closed before it make it slower
_PAGE = (select(Item.id).where(IS_COLLECTING).order_by(*_ORDER)
         .limit(QUEUE_PAGE).offset(bindparam("offset", type_=Integer)).correlate(None))
_LIVE_LEASES = select(func.count(Lease.id)).where(Lease.item_id == Item.id, Lease.expires_at > _T).scalar_subquery()
# the first item of the page open to the user: room for them, not reviewed by them, not read
_OPEN_TO_USER = (
    select(Item)
    .where(Item.id.in_(_PAGE), Item.status.in_(COLLECTING), Item.n_reviews + _LIVE_LEASES < Item.required_reviews,
           ~_reviewed_by(_UID), ~blindness.has_read(_ACTOR), Item.id.not_in(bindparam("passed", expanding=True)))
    .order_by(*_ORDER).limit(1)
)
_OPEN_SKIP = _OPEN_TO_USER.with_for_update(skip_locked=True, of=Item)
_OPEN_WAIT = _OPEN_TO_USER.with_for_update(of=Item)


def lease_next(s: Session, user: User, cfg: QueueSettings, tries: int = 8) -> Item | None:
    """The user's next item: one they already hold, else the fullest open item with room.

    The candidate is taken with `FOR UPDATE SKIP LOCKED` (PostgreSQL: concurrent callers
    pass over each other's candidates instead of queueing on them; SQLite ignores it, its
    writer is alone). `lease_item` then re-checks the room under the row lock; an item
    filled meanwhile is passed over for the next."""
    t = now()
    # every query below already ignores expired leases; the sweep only tidies rows and
    # statuses, so it need not run on every request
    if sweep_due(s, t):
        expire(s, t)
        _last_sweep[_sweep_key(s)] = t
    who = _who(user, t)
    held = s.scalar(_HELD_ITEM, who)
    if held is not None:
        lease_item(s, user, held, cfg)
        return held
    passed: list[int] = []
    for page in range(10_000):
        args = {**who, "offset": page * QUEUE_PAGE}
        while len(passed) < tries:
            args["passed"] = passed
            item = s.scalar(_OPEN_SKIP, args)
            if item is None:
                # SKIP LOCKED also passes over an item another request is deciding right now
                # (its row lock): "none" is only sure once such rows are waited for, and asked
                # again in a snapshot taken after they committed (the waiting statement still
                # counts, say, a lease its holder has since turned into a review)
                item = s.scalar(_OPEN_WAIT, args)
                if item is None:
                    item = s.scalar(_OPEN_SKIP, args)
            if item is None:
                break  # nothing open to this user on this page: the next page, if any
            try:
                lease_item(s, user, item, cfg)  # refuses before it writes anything
                return item
            except Stale:
                passed.append(item.id)
        if len(passed) >= tries or not s.scalars(_PAGE, {"offset": page * QUEUE_PAGE}).first():
            return None
    return None


KEY_CHARS = 100  # the idempotency_key columns' width


def idempotency_key(body: dict) -> str:
    key = str(body.get("idempotency_key") or "")
    if not key:
        raise Invalid("idempotency_key: required (any unique string per decision)", field="idempotency_key")
    if len(key) > KEY_CHARS:
        raise Invalid(f"idempotency_key: at most {KEY_CHARS} characters", field="idempotency_key")
    return key


def _values_for(item: Item, decision: str, fields: dict | None, reason: str | None,
                cfg: QueueSettings) -> tuple[str, dict | None, list[str]]:
    """(the decision as stored, its resolved values, the fields edited against the proposal)."""
    if decision not in DECISIONS:
        raise Invalid(f"decision: must be one of {list(DECISIONS)}, got {decision!r}", field="decision")
    if decision == Decision.flag:
        if not (reason or "").strip():
            raise Invalid("reason: a flag needs a reason", field="reason")
        return decision, None, []
    if decision == Decision.revise and not fields:
        raise Invalid("fields: a revision must change at least one field", field="fields")
    edits = fields if decision == Decision.revise else {}
    ctx = item.context or {}
    hz = ctx.get("control_hz", cfg.control_hz)
    try:
        values = resolve(item.proposal, edits, ctx.get("duration_s"), hz)
    except FieldError as e:
        raise Invalid(str(e), field=e.field) from None
    edited = edited_fields(item.proposal, values, hz) if decision == Decision.revise else []
    # confirming the model's values (e.g. its time set at the playhead) is an accept, not an edit
    return (Decision.revise if edited else Decision.accept), values, edited


def _same(r: Review, decision: str, values: dict | None, reason: str | None) -> bool:
    return r.decision == decision and r.values == values and (r.flag_reason or None) == ((reason or "").strip() or None)


# a first review takes a place: never more than K (the condition), in one statement (built once)
_ITEMS = Item.__table__
_TAKE_PLACE = (update(_ITEMS)
               .where(_ITEMS.c.id == bindparam("item_id"), _ITEMS.c.n_reviews < _ITEMS.c.required_reviews,
                      _ITEMS.c.status.in_(COLLECTING))
               .values(n_reviews=_ITEMS.c.n_reviews + 1, version=_ITEMS.c.version + 1, status=ItemStatus.reviewed))


def submit_review(s: Session, user: User, item_id: int, body: dict, cfg: QueueSettings) -> tuple[Review, bool]:
    """Store a decision; return (the review, whether it was a harmless repeat)."""
    item = get_item(s, item_id, lock=True)
    decision, key = body.get("decision"), idempotency_key(body)
    t = now()
    st = standing(s, user, item.id, t)
    mine = st.review
    if mine is not None and mine.idempotency_key == key:
        return mine, True
    decision, values, edited = _values_for(item, decision, body.get("fields"), body.get("reason"), cfg)
    reason = ((body.get("reason") or "").strip() or None) if decision == Decision.flag else None
    if mine is not None and _same(mine, decision, values, reason):
        return mine, True
    seen = int(body.get("version") or 0)
    current = mine.version if mine is not None else 0
    if seen != current:
        raise Stale(f"your review of item {item.id} changed since you loaded it (version {current}, you sent {seen})",
                    current={"version": current})
    if item.status not in COLLECTING:
        raise Stale(f"item {item.id} is {item.status}; it no longer takes reviews", current={"status": item.status})
    blindness.refuse_write(s, user, item, read=st.read)  # a first decision or a change to one
    before = _review_dict(mine) if mine is not None else None
    if mine is None:
        held = st.lease is not None and st.lease.expires_at > t
        if not held and item.n_reviews + st.others >= item.required_reviews:
            # leases are honoured: without one, a reviewer may not take a place others hold
            raise Stale(f"item {item.id} is held by other reviewers; take the next item instead")
        # `item` was read under its row lock in this transaction (SQLite: the one writer), so
        # the new counts are known without a reload, and set as the stored values; the status a
        # reviewed item has (`refresh_status`) is set by the same statement
        if not s.execute(_TAKE_PLACE, {"item_id": item.id}).rowcount:
            raise Stale(f"item {item.id} already has its {item.required_reviews} reviews")
        for name, value in (("n_reviews", item.n_reviews + 1), ("version", item.version + 1),
                            ("status", ItemStatus.reviewed)):
            set_committed_value(item, name, value)
        mine = Review(item_id=item.id, reviewer_id=user.id, decision=decision, values=values, edited=edited,
                      flag_reason=reason, idempotency_key=key, version=1)
        s.add(mine)
    else:
        mine.decision, mine.values, mine.edited, mine.flag_reason = decision, values, edited, reason
        mine.idempotency_key, mine.version, mine.updated_at = key, mine.version + 1, now()
        item.version += 1
    if st.lease is not None:
        s.delete(st.lease)
    audit.record(s, user.name, "review" if before is None else "review_changed", item, before, _review_dict(mine))
    if item.n_reviews >= item.required_reviews:
        close(s, item, cfg, actor=user.name)
    else:
        refresh_status(s, item)
    return mine, False


_REVIEW_VALUES = select(Review.values).where(Review.item_id == bindparam("item_id")).order_by(Review.id)  # built once


def close(s: Session, item: Item, cfg: QueueSettings, actor: str) -> None:
    """All K reviews are in: final when every field agrees, else conflict on the disputed ones."""
    values = s.scalars(_REVIEW_VALUES, {"item_id": item.id}).all()
    hz = (item.context or {}).get("control_hz", cfg.control_hz)
    agreed, disputed = agreement(list(values), cfg.time_tolerance_s, hz)
    before = item.status
    item.agreed, item.disputed = agreed, disputed
    if disputed:
        item.status = ItemStatus.conflict
    else:
        item.status, item.final, item.resolution, item.finalized_at = ItemStatus.final, agreed, Resolution.agreed, now()
    item.version += 1
    audit.record(s, actor, "status", item, {"status": before},
                 {"status": item.status, "disputed": disputed, "agreed": agreed})


def _review_dict(r: Review) -> dict:
    return {"decision": r.decision, "values": r.values, "edited": r.edited, "reason": r.flag_reason,
            "version": r.version}
