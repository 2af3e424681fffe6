"""The blindness rule of the review queue: one implementation, used by every route that
shows reviews (adjudication view, history, status) and by every write that adds or changes
a review (lease, next item, decision).

Inputs: a session, the acting user, an item (its episode: every revision of its key).
Outputs: the item, once the read is allowed and recorded; or Forbidden (403, a read) /
Stale (409, a write).
The rule:
- an episode's reviews are read by nobody, whatever their role, while any revision of it
  is still collecting reviews (reading revision 1 tells a revision-2 reviewer what the
  others chose);
- nobody reads the other decisions on an item they reviewed themselves, admins included
  (an admin has the database itself; the API gives no role an exemption);
- whoever reads an episode's reviews is recorded (`reviews_read` audit event) and may no
  longer lease, take or write a review of any revision of that episode: a first decision
  or a change to one they made before;
- statistics (`report.summary`, `views.progress`) count only reviews of closed items of
  episodes none of whose revisions is collecting (`closed`): agreement on an item still
  collecting says how its reviewers are voting.
Export writes final items only, so it never shows a collecting item's reviews.
"""

from __future__ import annotations

from sqlalchemy import ColumnElement, and_, exists, select
from sqlalchemy.orm import Session, aliased

from pipeline.review import audit
from pipeline.review.db import Event, Item, Review, User
from pipeline.review.errors import Forbidden, NotFound, Stale
from pipeline.vocab import COLLECTING

READ_REVIEWS = "reviews_read"  # audit event: this user has seen the reviews of this episode


def closed():
    """SQL condition: the item's reviews may be counted and shown: it is not collecting, nor is
    any other revision of its episode."""
    other = aliased(Item)
    return Item.status.not_in(COLLECTING) & ~exists().where(other.key == Item.key, other.status.in_(COLLECTING))


def has_read(actor: User | ColumnElement):
    """SQL condition: `actor` (a user, or an SQL expression of a user's name, e.g. a bound
    parameter of a statement built once) has read the reviews of this item's episode."""
    name = actor.name if isinstance(actor, User) else actor
    return exists().where(and_(Event.kind == READ_REVIEWS, Event.actor == name, Event.item_key == Item.key))


def refuse_read(s: Session, user: User, item: Item, whole_episode: bool) -> None:
    """Forbidden unless `user` may read the reviews of `item` (with `whole_episode`: of every
    revision of its episode, as history shows them)."""
    collecting = s.scalar(select(Item.revision).where(Item.key == item.key, Item.status.in_(COLLECTING))
                          .order_by(Item.revision).limit(1))
    if collecting is not None:
        which = "its reviews" if collecting == item.revision else f"the reviews of its episode's revision {collecting}"
        raise Forbidden(f"item {item.id}: {which} are still being collected; they stay hidden until then")
    read = select(Item.id).where(Item.key == item.key) if whole_episode else [item.id]
    mine = s.scalar(select(Item.id).join(Review, Review.item_id == Item.id)
                    .where(Item.id.in_(read), Review.reviewer_id == user.id).limit(1))
    if mine is not None:
        raise Forbidden(f"you reviewed item {mine}; its other decisions stay hidden from you")


def open_reviews(s: Session, user: User, item_id: int, whole_episode: bool = False) -> Item:
    """The item whose reviews `user` is about to read, after the rule; the read is recorded."""
    item = s.get(Item, item_id)
    if item is None:
        raise NotFound(f"no item {item_id}")
    refuse_read(s, user, item, whole_episode)
    seen = s.scalar(select(Event.id).where(Event.kind == READ_REVIEWS, Event.actor == user.name,
                                           Event.item_key == item.key).limit(1))
    if seen is None:
        audit.record(s, user.name, READ_REVIEWS, item)
    return item


def refuse_write(s: Session, user: User, item: Item, read: bool | None = None) -> None:
    """Stale (409) if `user` has read the reviews of `item`'s episode: checked on every lease
    and every decision, a first one or a change (`read`: `has_read` already asked, in the
    caller's own statement; None: asked here)."""
    if read is None:
        read = s.scalar(select(Item.id).where(Item.id == item.id, has_read(user))) is not None
    if read:
        raise Stale(f"you have read the reviews of item {item.id}'s episode; it needs reviewers who have not")
