"""The reads of every reviewer request, without the ORM: who is asking, the item, its tables.

Inputs: the engine, an item id, the acting user.
Outputs: the same answers as `auth.authenticate`'s lookups, `views.reviewer_view` (as JSON
bytes) and `workflow.get_item` (an `ItemInfo` with what the writes need).
Why: these run on every one of a reviewer's requests (rawsql.py says what they cost).
An item's episode data (key, instruction, proposal, context) never changes once enqueued
(a new proposal is a new item), so each server process keeps it, and its JSON, per item id;
one indexed read per request checks that the row is still the one cached (key, revision,
creation time: a database replaced under the server is noticed) and reads what changes.
"""

from __future__ import annotations

import json
import threading
import weakref
from collections import OrderedDict
from dataclasses import dataclass

from sqlalchemy import and_, select
from sqlalchemy.engine import Engine

from pipeline.review import views
from pipeline.review.audit import iso
from pipeline.review.db import COLLECTING, Item, Lease, Review, User, WebSession, now
from pipeline.review.errors import NotFound
from pipeline.review.rawsql import Stmt, param, reading

I, L, R, U, S = Item.__table__, Lease.__table__, Review.__table__, User.__table__, WebSession.__table__
_USER_COLS = (U.c.id, U.c.name, U.c.role, U.c.token_hash, U.c.active, U.c.created_at)

BY_TOKEN = Stmt(select(*_USER_COLS).where(U.c.token_hash == param("h")))
BY_SESSION = Stmt(select(S.c.csrf, S.c.expires_at, *_USER_COLS)
                  .select_from(S.outerjoin(U, U.c.id == S.c.user_id)).where(S.c.id_hash == param("h")))
ITEM = Stmt(select(I.c.id, I.c.key, I.c.revision, I.c.created_at, I.c.suite, I.c.task, I.c.episode_id, I.c.instruction,
                   I.c.quarantined, I.c.quarantine_reason, I.c.quarantine_detail, I.c.proposal, I.c.context)
             .where(I.c.id == param("iid")))
_STAMP = (I.c.key, I.c.revision, I.c.created_at)
STAMP = Stmt(select(*_STAMP).where(I.c.id == param("iid")))
# the reviewer's view of an item in one statement (one snapshot): the item's state, the
# reviewer's lease and own review (each unique per item and person)
MINE = Stmt(
    select(*_STAMP, I.c.status, L.c.expires_at, R.c.id.label("review_id"), R.c.decision, R.c["values"], R.c.edited,
           R.c.flag_reason, R.c.version, R.c.updated_at)
    .select_from(I.outerjoin(L, and_(L.c.item_id == I.c.id, L.c.user_id == param("uid")))
                 .outerjoin(R, and_(R.c.item_id == I.c.id, R.c.reviewer_id == param("uid"))))
    .where(I.c.id == param("iid"))
)


@dataclass(frozen=True, slots=True)
class Actor:
    """The acting user: the attributes of a `User` row, without the ORM's instance state
    (building an ORM instance per request cost more than the query that found it)."""

    id: int
    name: str
    role: str
    token_hash: str
    active: bool
    created_at: float


def user_from(row) -> Actor:
    return Actor(row.id, row.name, row.role, row.token_hash, bool(row.active), row.created_at)


@dataclass(frozen=True)
class ItemInfo:
    """What never changes about an item (what `workflow.get_item`'s callers read of it)."""

    id: int
    key: str
    revision: int
    created_at: float
    proposal: dict
    context: dict
    base_json: bytes  # `views._base(item)` as JSON, without its closing brace

    @property
    def stamp(self) -> tuple:
        return self.key, self.revision, self.created_at


def dumps(obj) -> bytes:
    # as starlette's JSONResponse encodes
    return json.dumps(obj, ensure_ascii=False, allow_nan=False, indent=None, separators=(",", ":")).encode("utf-8")


class _Items:
    """Per engine: item id -> ItemInfo, the most recent `size` items."""

    def __init__(self, size: int = 4096):
        self.size = size
        self.data: OrderedDict[int, ItemInfo] = OrderedDict()
        self.lock = threading.Lock()

    def get(self, item_id: int, stamp: tuple) -> ItemInfo | None:
        with self.lock:
            info = self.data.get(item_id)
            if info is None or info.stamp != tuple(stamp):
                return None
            self.data.move_to_end(item_id)
            return info

    def put(self, info: ItemInfo) -> None:
        with self.lock:
            self.data[info.id] = info
            self.data.move_to_end(info.id)
            while len(self.data) > self.size:
                self.data.popitem(last=False)


_CACHES: weakref.WeakKeyDictionary[Engine, _Items] = weakref.WeakKeyDictionary()
_CACHES_GUARD = threading.Lock()


def _cache(engine: Engine) -> _Items:
    c = _CACHES.get(engine)
    if c is None:
        with _CACHES_GUARD:
            c = _CACHES.setdefault(engine, _Items())
    return c


def _load(engine: Engine, item_id: int) -> ItemInfo:
    with reading(engine) as cur:
        item = cur.first(ITEM, iid=item_id)  # has the attributes views._base reads
    if item is None:
        raise NotFound(f"no item {item_id}")
    return ItemInfo(id=item.id, key=item.key, revision=item.revision, created_at=item.created_at,
                    proposal=item.proposal, context=item.context or {}, base_json=dumps(views._base(item))[:-1])


def info_for(engine: Engine, item_id: int, stamp) -> ItemInfo:
    """The cached ItemInfo if it matches `stamp` (key, revision, created_at just read), else reloaded."""
    cache = _cache(engine)
    info = cache.get(item_id, stamp)
    if info is None:
        info = _load(engine, item_id)
        cache.put(info)
    return info


def item_info(engine: Engine, item_id: int) -> ItemInfo:
    """The item's unchanging data (404 when there is no such item)."""
    with reading(engine) as cur:
        stamp = cur.first(STAMP, iid=item_id)
    if stamp is None:
        raise NotFound(f"no item {item_id}")
    return info_for(engine, item_id, stamp)


def reviewer_view_json(engine: Engine, item_id: int, user: User | Actor) -> bytes:
    """`views.reviewer_view` of the item for `user`, encoded."""
    with reading(engine) as cur:
        row = cur.first(MINE, iid=item_id, uid=user.id)
    if row is None:
        raise NotFound(f"no item {item_id}")
    info = info_for(engine, item_id, (row.key, row.revision, row.created_at))
    mine = None if row.review_id is None else {
        "decision": row.decision, "values": row.values, "edited": row.edited, "reason": row.flag_reason,
        "version": row.version, "at": iso(row.updated_at),
    }
    expires = row.expires_at
    state = {
        "state": "open" if row.status in COLLECTING else "closed",
        "lease_expires_at": iso(expires) if expires is not None and expires > now() else None,
        "my_review": mine,
        "version": row.version if mine is not None else 0,
    }
    return info.base_json + b"," + dumps(state)[1:]
