"""Putting an episode's proposal into the review queue, and revisions.

Inputs: an episode key, the model's proposal (values + model/prompt version; values may
be missing for quarantined outputs), the review context (media paths, phases, events):
`proposal.Proposal` / `proposal.ReviewContext` or dicts of their fields, validated here;
one that does not fit raises `proposal.InvalidProposal` naming the field and nothing is written.
Outputs: an `items` row (status pending) and an `enqueued` or `revision` audit event.
Invariants: enqueueing the same proposal again changes nothing (stage 3 may be rerun
after a crash); a different proposal for a key becomes a new revision: a final item
stays final and untouched, an unfinished one is superseded (taken out of the queue).
"""

from __future__ import annotations

import hashlib
import json

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from pipeline.layout import parse_key
from pipeline.review import audit
from pipeline.review.db import Item, Lease
from pipeline.review.proposal import Proposal, ReviewContext, checked
from pipeline.vocab import ItemStatus


def proposal_hash(proposal: dict, quarantined: bool, reason: str | None) -> str:
    blob = json.dumps({"p": proposal, "q": quarantined, "r": reason}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()


def enqueue(
    s: Session,
    *,
    key: str,
    instruction: str,
    proposal: Proposal | dict,
    context: ReviewContext | dict,
    required_reviews: int,
    quarantined: bool = False,
    reason: str | None = None,
    detail: str | None = None,
    actor: str = "stage3",
) -> tuple[Item, bool]:
    """Return (the item for this proposal, whether a new item was created)."""
    suite, task, ep = parse_key(key)
    proposal, context = checked(Proposal, proposal, "proposal", key), checked(ReviewContext, context, "context", key)
    h = proposal_hash(proposal, quarantined, reason)
    latest = s.scalar(select(Item).where(Item.key == key).order_by(Item.revision.desc()).limit(1))
    if latest is not None and latest.proposal_hash == h:
        return latest, False
    item = Item(
        key=key, revision=(latest.revision + 1) if latest else 1, suite=suite, task=task, episode_id=ep,
        instruction=instruction, status=ItemStatus.pending, version=1, required_reviews=required_reviews, n_reviews=0,
        quarantined=quarantined, quarantine_reason=reason, quarantine_detail=detail,
        proposal=proposal, proposal_hash=h, context=context,
    )
    s.add(item)
    s.flush()
    if latest is None:
        audit.record(s, actor, "enqueued", item, None, {"status": ItemStatus.pending, "proposal": proposal})
        return item, True
    if latest.status != ItemStatus.final:  # a final item is never written again
        latest.superseded_by = item.id
        # reviews of an outdated proposal are kept (history) but the item leaves the queue
        s.execute(delete(Lease).where(Lease.item_id == latest.id))
        audit.record(s, actor, "status", latest, {"status": latest.status}, {"status": ItemStatus.superseded})
        latest.status = ItemStatus.superseded
        latest.version += 1
    audit.record(s, actor, "revision", item, {"revision": latest.revision, "proposal": latest.proposal},
                 {"revision": item.revision, "proposal": proposal})
    return item, True
