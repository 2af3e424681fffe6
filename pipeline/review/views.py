"""What each person is shown: the reviewer's item, the adjudicator's item, the queue.

Inputs: a read session, the item, the viewing user.
Outputs: JSON-ready dicts.
Invariants: the reviewer view never contains another reviewer's decision, count or the
item's agreement state (only "open" or "closed"); the adjudication view, for someone who
did not review the item, shows every reviewer's values beside the model's, per field.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from sqlalchemy import and_, bindparam, func, select
from sqlalchemy.orm import Session, defer

from pipeline.review import blindness
from pipeline.review.audit import iso
from pipeline.review.db import Item, Lease, Review, User, now
from pipeline.review.errors import NotFound
from pipeline.review.fields import CATEGORIES, FIELDS, LEVELS, agreement, grid_time, snap_step
from pipeline.stage3.inputs import CAMERAS
from pipeline.vocab import COLLECTING, ItemStatus


def _media(ctx: dict) -> dict:
    def url(rel: str | None) -> str | None:
        return f"/media/{rel}" if rel else None

    hz = ctx.get("control_hz", 20)
    duration = ctx.get("duration_s")
    videos = ctx.get("videos") or {}
    return {
        "videos": {cam: url(p) for cam, p in videos.items()},
        # every review camera, in a fixed order, null where the episode has no such video
        "cameras": [{"name": cam, "url": url(videos.get(cam))} for cam in CAMERAS],
        # the failure time is set on the control grid: one step = 1/control_hz seconds
        "control_step_s": round(1 / hz, 6),
        "n_steps": None if duration is None else snap_step(duration, hz) + 1,
        "has_frames": bool(ctx.get("frames")),
        "has_evidence": bool(ctx.get("evidence")),
        "fps": ctx.get("fps"),
        "control_hz": ctx.get("control_hz", 20),
        "duration_s": ctx.get("duration_s"),
        "phases": ctx.get("phases"),
        "events": ctx.get("events") or [],
    }


def _proposal_step(item: Item) -> dict | None:
    """The model's time on the control grid (what accepting it stores)."""
    t = (item.proposal or {}).get("fail_time_s")
    if t is None:
        return None
    hz = (item.context or {}).get("control_hz", 20)
    step = snap_step(float(t), hz)
    return {"fail_step": step, "fail_time_s": grid_time(step, hz)}


_BASE: OrderedDict[tuple, dict] = OrderedDict()  # (id, key, revision, created_at) -> _base(item)
_BASE_MAX = 4096
_BASE_GUARD = threading.Lock()


def _base(item: Item) -> dict:
    """What never changes about an item (a new proposal is a new item), built once per
    (item, revision) and process: the same dict for every reviewer (read only)."""
    key = (item.id, item.key, item.revision, item.created_at)  # the creation time: another database's item 1 differs
    with _BASE_GUARD:
        out = _BASE.get(key)
        if out is not None:
            _BASE.move_to_end(key)
            return out
    out = _build_base(item)
    with _BASE_GUARD:
        _BASE[key] = out
        while len(_BASE) > _BASE_MAX:
            _BASE.popitem(last=False)
    return out


def _build_base(item: Item) -> dict:
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
        "proposal_step": _proposal_step(item),
        "media": _media(item.context or {}),
        "choices": {"recovery_level": LEVELS, "failure_category": CATEGORIES, "fields": list(FIELDS)},
    }


# built once, values bound per call (see `workflow._STANDING`)
_REVIEWER_ROW = (
    select(Item, Review, Lease)
    .outerjoin(Review, and_(Review.item_id == Item.id, Review.reviewer_id == bindparam("user_id")))
    .outerjoin(Lease, and_(Lease.item_id == Item.id, Lease.user_id == bindparam("user_id")))
    .where(Item.id == bindparam("item_id"))
)


def reviewer_view(s: Session, item_id: int, user: User) -> dict:
    """Item `item_id` as `user` reviews it (404 if there is none): the item, their own review
    and their lease, read in one statement (each is unique per (item, person))."""
    row = s.execute(_REVIEWER_ROW, {"user_id": user.id, "item_id": item_id}).first()
    if row is None:
        raise NotFound(f"no item {item_id}")
    item, mine, lease = row
    t = now()
    out = {**_base(item)}
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
    out = {**_base(item)}
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


# the queue lists rows of hundreds of items: their proposal and context (phases, events) are
# not shown, and decoding them cost most of the page
_LIST_ONLY = defer(Item.proposal), defer(Item.context), defer(Item.agreed), defer(Item.final)


def queue(s: Session, user: User, can_adjudicate: bool, limit: int = 200) -> dict:
    """The queue page of one user: held items, items open to them, their past decisions, conflicts."""
    t = now()
    held = s.scalars(
        select(Item).options(*_LIST_ONLY).join(Lease, Lease.item_id == Item.id)
        .where(Lease.user_id == user.id, Lease.expires_at > t, Item.status.in_(COLLECTING)).order_by(Item.id)
    ).all()
    mine = select(Review.item_id).where(Review.reviewer_id == user.id)
    leases = select(func.count(Lease.id)).where(Lease.item_id == Item.id, Lease.expires_at > t).scalar_subquery()
    open_q = (select(Item).where(Item.status.in_(COLLECTING), Item.n_reviews + leases < Item.required_reviews,
                                 Item.id.not_in(mine), Item.id.not_in([i.id for i in held]), ~blindness.has_read(user)))
    n_open = s.scalar(select(func.count()).select_from(open_q.subquery())) or 0
    available = s.scalars(open_q.options(*_LIST_ONLY).order_by(Item.quarantined, Item.n_reviews.desc(), Item.id).limit(limit)).all()
    done = s.execute(
        select(Item, Review).options(*_LIST_ONLY, defer(Review.values), defer(Review.edited))
        .join(Review, Review.item_id == Item.id)
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
            select(Item).options(*_LIST_ONLY).where(Item.status.in_((ItemStatus.conflict, ItemStatus.adjudicating)), Item.id.not_in(mine)).order_by(Item.id)
        ).all()
        out["conflicts"] = [
            {**_row(i), "disputed": i.disputed or [], "status": i.status,
             "claimed_by_other": i.status == ItemStatus.adjudicating and i.adjudicator_id != user.id
             and (i.adjudication_lease_until or 0) > t}
            for i in conflicts
        ]
    return out


def _open_to(user: User, t: float):
    """Items `user` may still take: collecting, room for a reviewer, not reviewed by them."""
    mine = select(Review.item_id).where(Review.reviewer_id == user.id)
    leases = select(func.count(Lease.id)).where(Lease.item_id == Item.id, Lease.expires_at > t).scalar_subquery()
    held = select(Lease.item_id).where(Lease.user_id == user.id, Lease.expires_at > t)
    return Item.status.in_(COLLECTING) & Item.id.not_in(mine) & ~blindness.has_read(user) & (
        (Item.n_reviews + leases < Item.required_reviews) | Item.id.in_(held))


def day_start(t: float) -> float:
    """00:00 UTC of the day of `t` ("today" is the same day for every reviewer and server)."""
    return t - t % 86400


_PAIRS: dict[tuple, tuple[int, int, tuple[int, ...]]] = {}  # see progress


def _count_pairs(s: Session, user_id: int, item_ids: list[int], tolerance_s: float, control_hz: int,
                 db: str) -> dict[tuple, tuple]:
    """Per closed item: (pairs of me and another reviewer, pairs agreeing on every field,
    pairs agreeing per field), by the queue's own rule (`fields.agreement`); kept in _PAIRS."""
    # the item's control rate only, not its whole context (phases, events)
    rows = s.execute(select(Review.item_id, Item.created_at, Review.reviewer_id, Review.values,
                            Item.context["control_hz"].as_integer())
                     .join(Item, Item.id == Review.item_id).where(Review.item_id.in_(item_ids))
                     .order_by(Review.item_id, Review.id)).all()
    by_item: dict[tuple, list] = {}
    for item_id, created, reviewer_id, values, hz in rows:
        by_item.setdefault((item_id, created), []).append((reviewer_id, values, control_hz if hz is None else hz))
    if len(_PAIRS) > 500_000:
        _PAIRS.clear()
    out = {}
    for (item_id, created), reviews in by_item.items():
        mine = next(v for r, v, _ in reviews if r == user_id)
        n = whole = 0
        per_field = [0] * len(FIELDS)
        for r, other, hz in reviews:
            if r == user_id:
                continue
            _, disputed = agreement([mine, other], tolerance_s, hz)
            n += 1
            whole += not disputed
            for j, f in enumerate(FIELDS):
                per_field[j] += f not in disputed
        out[(db, user_id, item_id, created, tolerance_s, control_hz)] = (n, whole, tuple(per_field))
    _PAIRS.update(out)
    return out


def progress(s: Session, user: User, tolerance_s: float, control_hz: int = 20) -> dict:
    """One reviewer's own progress: decisions today, items left to them, and how often their
    values agreed with each other reviewer's on items that have closed (all K reviews in).

    Agreement is per pair (me, another reviewer) and per field, by the queue's own rule
    (`fields.agreement`); open items are left out, so nothing about them is revealed."""
    t = now()
    today = day_start(t)
    done_today = s.scalar(select(func.count(Review.id)).where(Review.reviewer_id == user.id,
                                                              Review.created_at >= today)) or 0
    left = s.scalar(select(func.count(Item.id)).where(_open_to(user, t))) or 0
    closed = s.execute(select(Item.id, Item.created_at).join(Review, Review.item_id == Item.id).where(
        Review.reviewer_id == user.id, blindness.closed(), Item.n_reviews >= Item.required_reviews)).all()
    # a closed item's reviews never change: its pair counts are computed once per process
    # (keyed by the database and the item's creation time too), so this costs what the
    # items closed since the last call cost, not the reviewer's whole day
    db = s.get_bind().url.render_as_string(hide_password=True)
    keys = [(db, user.id, item_id, created, tolerance_s, control_hz) for item_id, created in closed]
    per_item = {k: _PAIRS.get(k) for k in keys}
    todo = [k[2] for k, v in per_item.items() if v is None]
    for i in range(0, len(todo), 500):
        per_item.update(_count_pairs(s, user.id, todo[i:i + 500], tolerance_s, control_hz, db))
    pairs, whole = 0, 0
    per_field = dict.fromkeys(FIELDS, 0)
    for n, w, by_field in per_item.values():
        pairs += n
        whole += w
        for f, c in zip(FIELDS, by_field):
            per_field[f] += c
    share = (lambda n: round(n / pairs, 4) if pairs else None)
    return {
        "done_today": done_today,
        "day_start": iso(today),
        "left": left,
        "agreement": {"closed_items": len(closed), "pairs": pairs, "all_fields": share(whole),
                      "by_field": {f: share(n) for f, n in per_field.items()}},
    }


TABLES = ("evidence", "frames")  # the tables an item's context may name
_TABLE_PATHS = (select(*(Item.context[kind].as_string() for kind in TABLES))
                .where(Item.id == bindparam("item_id")))  # built once (see `_REVIEWER_ROW`)


def table_paths(s: Session, item_id: int) -> dict[str, str]:
    """The paths (under the run folder) of an item's tables, kind -> path ("" if it has none),
    read alone, not with the rest of the item (404 if there is no item)."""
    row = s.execute(_TABLE_PATHS, {"item_id": item_id}).first()
    if row is None:
        raise NotFound(f"no item {item_id}")
    return {kind: path or "" for kind, path in zip(TABLES, row)}


def video_paths(s: Session) -> set[str]:
    """Every video an item shows (its `context.videos`): all that `/media/` may serve."""
    return {p for ctx in s.scalars(select(Item.context)) for p in ((ctx or {}).get("videos") or {}).values() if p}


def counts(s: Session) -> dict:
    rows = s.execute(select(Item.status, Item.quarantined, func.count()).group_by(Item.status, Item.quarantined)).all()
    out: dict = {"total": 0, "quarantined": 0, "by_status": {}}
    for status, quarantined, n in rows:
        out["by_status"][status] = out["by_status"].get(status, 0) + n
        out["total"] += n
        out["quarantined"] += n if quarantined else 0
    return out
