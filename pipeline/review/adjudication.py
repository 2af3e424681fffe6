"""The adjudicating half of the state machine: conflict -> adjudicating -> final.

Inputs: a write session, an adjudicator (role checked by the caller), the item.
Invariants:
- the adjudicator is never one of the item's reviewers (403);
- only the disputed fields are decided: a missing disputed field or an extra field is a
  422 naming it; a rationale is required;
- the decision carries the item's version; an outdated one is a 409; a claim by another
  adjudicator holds the item until it expires;
- one adjudication per item (unique in the database), after which the item is final and
  immutable; the same decision again (same idempotency key) is answered, not repeated.
- `exclude` ends an item as final without values (not a usable failure); export skips it.
"""

from __future__ import annotations

from sqlalchemy import select
from sqlalchemy.orm import Session

from pipeline.review import audit
from pipeline.review.db import Adjudication, Item, Review, User, now
from pipeline.review.errors import Forbidden, Invalid, Stale
from pipeline.review.fields import FieldError, snap_step, validate_field
from pipeline.review.workflow import QueueSettings, get_item, idempotency_key
from pipeline.vocab import ItemStatus, Resolution

CLAIM_SECONDS = 1800


def _check_not_reviewer(s: Session, user: User, item: Item) -> None:
    if s.scalar(select(Review.id).where(Review.item_id == item.id, Review.reviewer_id == user.id)):
        raise Forbidden(f"you reviewed item {item.id}; another adjudicator must decide it")


def _check_claimable(user: User, item: Item, t: float) -> None:
    if item.status == ItemStatus.adjudicating and item.adjudicator_id != user.id and (item.adjudication_lease_until or 0) > t:
        raise Stale(f"item {item.id} is being adjudicated by someone else", current={"version": item.version})
    if item.status not in (ItemStatus.conflict, ItemStatus.adjudicating):
        raise Stale(f"item {item.id} is {item.status}, not in conflict", current={"status": item.status})


def claim(s: Session, user: User, item_id: int) -> Item:
    item = get_item(s, item_id, lock=True)
    _check_not_reviewer(s, user, item)
    t = now()
    _check_claimable(user, item, t)
    if item.status != ItemStatus.adjudicating or item.adjudicator_id != user.id:
        audit.record(s, user.name, "claimed", item, {"status": item.status}, {"status": ItemStatus.adjudicating})
        item.status, item.adjudicator_id = ItemStatus.adjudicating, user.id
        item.version += 1
    item.adjudication_lease_until = t + CLAIM_SECONDS
    return item


def adjudicate(s: Session, user: User, item_id: int, body: dict, cfg: QueueSettings) -> tuple[Adjudication, bool]:
    """Decide the disputed fields; return (the adjudication, whether it was a harmless repeat)."""
    item = get_item(s, item_id, lock=True)
    key = idempotency_key(body)
    done = s.scalar(select(Adjudication).where(Adjudication.item_id == item.id))
    if done is not None and done.idempotency_key == key:
        return done, True
    _check_not_reviewer(s, user, item)
    if item.status == ItemStatus.final:
        raise Stale(f"item {item.id} is final and cannot be edited; a new revision goes through the queue",
                    current={"status": item.status})
    _check_claimable(user, item, now())
    if int(body.get("version") or 0) != item.version:
        raise Stale(f"item {item.id} changed since you loaded it (version {item.version})",
                    current={"version": item.version})
    rationale = (body.get("rationale") or "").strip()
    if not rationale:
        raise Invalid("rationale: an adjudication needs a rationale", field="rationale")
    exclude = bool(body.get("exclude"))
    values = _validated(item, body.get("fields") or {}, exclude, cfg)
    adj = Adjudication(item_id=item.id, adjudicator_id=user.id, values=values, exclude=exclude,
                       rationale=rationale, idempotency_key=key)
    s.add(adj)
    before = {"status": item.status, "agreed": item.agreed, "disputed": item.disputed}
    if exclude:
        item.final, item.resolution = None, Resolution.excluded
    else:
        final = {**(item.agreed or {}), **values}
        final["fail_step"] = snap_step(final["fail_time_s"], (item.context or {}).get("control_hz", cfg.control_hz))
        item.final, item.resolution = final, Resolution.adjudicated
    item.status, item.adjudicator_id, item.adjudication_lease_until = ItemStatus.final, user.id, None
    item.finalized_at, item.version = now(), item.version + 1
    s.flush()
    audit.record(s, user.name, "adjudicated", item, before,
                 {"status": ItemStatus.final, "final": item.final, "resolution": item.resolution, "values": values},
                 detail=rationale)
    return adj, False


def _validated(item: Item, fields: dict, exclude: bool, cfg: QueueSettings) -> dict:
    disputed = list(item.disputed or [])
    extra = [f for f in fields if f not in disputed]
    if extra:
        raise Invalid(f"{extra[0]}: not disputed; only {disputed} are adjudicated", field=extra[0])
    if exclude:
        return {}
    missing = [f for f in disputed if f not in fields]
    if missing:
        raise Invalid(f"{missing[0]}: disputed; the adjudication must decide it", field=missing[0])
    duration = (item.context or {}).get("duration_s")
    hz = (item.context or {}).get("control_hz", cfg.control_hz)
    try:
        return {f: validate_field(f, fields[f], duration, hz) for f in disputed}
    except FieldError as e:
        raise Invalid(str(e), field=e.field) from None
