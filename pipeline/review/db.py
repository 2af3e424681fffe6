"""The review queue's database: tables, the engine factory and the two kinds of session.

Inputs: a SQLAlchemy URL (default: SQLite at `<run>/stage3/review.sqlite`; a team's
PostgreSQL as `postgresql+psycopg://user@host/db`).
Outputs: an Engine whose schema is at the newest migration (`migrations/`: an older
database is upgraded in place, the same way on both backends).
Invariants (enforced by the database, not only by code):
- one review per reviewer per item (`uq_review_item_reviewer`);
- one adjudication per item (`adjudications.item_id` unique);
- one item per (episode key, revision) (`uq_item_key_revision`);
- the audit log is append-only (triggers abort UPDATE and DELETE on `events`).
SQLite runs in WAL mode with a busy timeout; its write transactions start with BEGIN
IMMEDIATE (use `write_session`) so two writers queue instead of failing on a lock upgrade,
and the writers of one process queue first on the engine's own lock (`_sqlite_setup`).
PostgreSQL runs READ COMMITTED: the workflow takes the item's row lock (`FOR UPDATE`)
before it checks and changes an item. Times are UNIX seconds (float).
"""

from __future__ import annotations

import os
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import (
    JSON,
    Boolean,
    Float,
    ForeignKey,
    Index,
    Integer,
    String,
    Text,
    UniqueConstraint,
    create_engine,
    event,
    literal,
    text,
)
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column

from pipeline.layout import RunLayout
from pipeline.vocab import COLLECTING, ItemStatus



def now() -> float:
    return time.time()


class Base(DeclarativeBase):
    type_annotation_map = {dict: JSON, list: JSON}


class User(Base):
    __tablename__ = "users"
    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))  # reviewer | adjudicator | admin
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    created_at: Mapped[float] = mapped_column(Float, default=now)


class WebSession(Base):
    __tablename__ = "sessions"
    id_hash: Mapped[str] = mapped_column(String(64), primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"))
    csrf: Mapped[str] = mapped_column(String(64))
    expires_at: Mapped[float] = mapped_column(Float)


class Item(Base):
    __tablename__ = "items"
    __table_args__ = (UniqueConstraint("key", "revision", name="uq_item_key_revision"),)
    id: Mapped[int] = mapped_column(primary_key=True)
    key: Mapped[str] = mapped_column(String(300), index=True)
    revision: Mapped[int] = mapped_column(Integer, default=1)
    suite: Mapped[str] = mapped_column(String(64))
    task: Mapped[str] = mapped_column(String(200))
    episode_id: Mapped[str] = mapped_column(String(100))
    instruction: Mapped[str] = mapped_column(Text)
    status: Mapped[str] = mapped_column(String(16), default=ItemStatus.pending, index=True)  # ItemStatus
    version: Mapped[int] = mapped_column(Integer, default=1)
    required_reviews: Mapped[int] = mapped_column(Integer)
    n_reviews: Mapped[int] = mapped_column(Integer, default=0)
    quarantined: Mapped[bool] = mapped_column(Boolean, default=False)
    quarantine_reason: Mapped[str | None] = mapped_column(String(64), nullable=True)
    quarantine_detail: Mapped[str | None] = mapped_column(Text, nullable=True)
    proposal: Mapped[dict] = mapped_column(JSON)  # the model's values + model/prompt version
    proposal_hash: Mapped[str] = mapped_column(String(64))
    context: Mapped[dict] = mapped_column(JSON)  # media paths, phases, events, duration, fps
    disputed: Mapped[list | None] = mapped_column(JSON, nullable=True)
    agreed: Mapped[dict | None] = mapped_column(JSON, nullable=True)  # values all reviewers share
    final: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    resolution: Mapped[str | None] = mapped_column(String(16), nullable=True)  # agreed|adjudicated|excluded
    adjudicator_id: Mapped[int | None] = mapped_column(ForeignKey("users.id"), nullable=True)
    adjudication_lease_until: Mapped[float | None] = mapped_column(Float, nullable=True)
    superseded_by: Mapped[int | None] = mapped_column(Integer, nullable=True)
    created_at: Mapped[float] = mapped_column(Float, default=now)
    finalized_at: Mapped[float | None] = mapped_column(Float, nullable=True)


# "still collecting" spelled as "in none of the other states", with the values in the SQL text,
# not bound: a partial index serves only a query whose WHERE repeats the index's own condition
# as written (a bound value is not; nor is it known to PostgreSQL's generic plan of a prepared
# statement), and SQLite's planner, without statistics, would serve an `IN` from the status
# index and sort every open item instead (a `NOT IN` it cannot serve from an index)
IS_COLLECTING = Item.status.not_in([literal(str(v), literal_execute=True) for v in ItemStatus if v not in COLLECTING])
# the open items in the queue's order (`workflow.lease_next`): its first rows are the next
# items, without a sort and without passing over the items that have closed (those are not in it)
Index("ix_items_queue_open", Item.quarantined, Item.n_reviews.desc(), Item.id,
      sqlite_where=IS_COLLECTING, postgresql_where=IS_COLLECTING)


class Lease(Base):
    __tablename__ = "leases"
    __table_args__ = (UniqueConstraint("item_id", "user_id", name="uq_lease_item_user"),)
    id: Mapped[int] = mapped_column(primary_key=True)
    item_id: Mapped[int] = mapped_column(ForeignKey("items.id"), index=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"))
    expires_at: Mapped[float] = mapped_column(Float, index=True)
    taken_at: Mapped[float] = mapped_column(Float, default=now)  # renewals end at taken_at + lease_max_s


class Review(Base):
    __tablename__ = "reviews"
    __table_args__ = (UniqueConstraint("item_id", "reviewer_id", name="uq_review_item_reviewer"),)
    id: Mapped[int] = mapped_column(primary_key=True)
    item_id: Mapped[int] = mapped_column(ForeignKey("items.id"), index=True)
    reviewer_id: Mapped[int] = mapped_column(ForeignKey("users.id"))
    decision: Mapped[str] = mapped_column(String(8))  # accept | revise | flag
    values: Mapped[dict | None] = mapped_column(JSON, nullable=True)  # None for a flag
    edited: Mapped[list] = mapped_column(JSON, default=list)
    flag_reason: Mapped[str | None] = mapped_column(Text, nullable=True)
    idempotency_key: Mapped[str] = mapped_column(String(100))
    version: Mapped[int] = mapped_column(Integer, default=1)
    created_at: Mapped[float] = mapped_column(Float, default=now)
    updated_at: Mapped[float] = mapped_column(Float, default=now)


class Adjudication(Base):
    __tablename__ = "adjudications"
    id: Mapped[int] = mapped_column(primary_key=True)
    item_id: Mapped[int] = mapped_column(ForeignKey("items.id"), unique=True)
    adjudicator_id: Mapped[int] = mapped_column(ForeignKey("users.id"))
    values: Mapped[dict] = mapped_column(JSON)  # the disputed fields only
    exclude: Mapped[bool] = mapped_column(Boolean, default=False)
    rationale: Mapped[str] = mapped_column(Text)
    idempotency_key: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[float] = mapped_column(Float, default=now)


class Event(Base):
    __tablename__ = "events"
    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[float] = mapped_column(Float, default=now, index=True)
    actor: Mapped[str] = mapped_column(String(64))
    kind: Mapped[str] = mapped_column(String(32))
    item_id: Mapped[int | None] = mapped_column(Integer, nullable=True, index=True)
    item_key: Mapped[str | None] = mapped_column(String(300), nullable=True, index=True)
    before: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    after: Mapped[dict | None] = mapped_column(JSON, nullable=True)
    model: Mapped[str | None] = mapped_column(String(200), nullable=True)
    prompt_name: Mapped[str | None] = mapped_column(String(200), nullable=True)
    prompt_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    detail: Mapped[str] = mapped_column(Text, default="")


def default_url(run_dir: str | Path) -> str:
    return f"sqlite:///{RunLayout(Path(run_dir).resolve()).stage3.review_db}"


def make_engine(url: str, busy_timeout_ms: int = 10_000) -> Engine:
    """An engine whose schema is migrated to the newest revision; SQLite gets WAL, busy
    timeout, IMMEDIATE writes and a private (0600) file."""
    sqlite = url.startswith("sqlite")
    if sqlite and ":memory:" not in url and url.count("/") >= 3:
        path = Path(url.split("///", 1)[1].split("?", 1)[0])
        path.parent.mkdir(parents=True, exist_ok=True)
        _private_files(path)
    kwargs: dict = {"pool_size": 32, "max_overflow": 16} if not sqlite or ":memory:" not in url else {}
    if not sqlite:
        kwargs["pool_pre_ping"] = True  # a team's server restarts; a dead pooled connection is replaced
    engine = create_engine(url, connect_args={"timeout": busy_timeout_ms / 1000} if sqlite else {}, **kwargs)
    if sqlite:
        _sqlite_setup(engine, busy_timeout_ms)
    from pipeline.review.migrations import upgrade

    upgrade(engine)
    return engine


def _private_files(path: Path) -> None:
    """The database (reviews, token hashes) readable by its owner only: 0600.

    SQLite gives its -wal and -shm files the database file's mode, so creating that file
    0600 before SQLite opens it covers all three; files of an older run are tightened.
    """
    if not path.exists():
        os.close(os.open(path, os.O_CREAT | os.O_WRONLY, 0o600))  # an empty file is an empty database
    for p in (path, path.with_name(path.name + "-wal"), path.with_name(path.name + "-shm")):
        if p.exists() and p.stat().st_mode & 0o077:
            os.chmod(p, 0o600)


_GATE_HELD = "review_write_gate"  # in a connection's info while it holds its engine's writer gate


def _sqlite_setup(engine: Engine, busy_timeout_ms: int) -> None:
    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn, _record):
        # let SQLAlchemy emit BEGIN itself (pysqlite's implicit BEGIN is deferred and racy)
        dbapi_conn.isolation_level = None
        cur = dbapi_conn.cursor()
        cur.execute("PRAGMA journal_mode=WAL")
        cur.execute(f"PRAGMA busy_timeout={int(busy_timeout_ms)}")
        cur.execute("PRAGMA foreign_keys=ON")
        cur.execute("PRAGMA synchronous=NORMAL")
        cur.close()

    # The writers of one process queue on this lock, not in SQLite's busy handler: that
    # handler sleeps 1, 2, 5, ... up to 100 ms between tries, so under a steady stream of
    # writers the sleeping, not the work, made the wait (decision p95 215 ms at 24
    # decisions/s, `benchmarks/review_load.py`). Processes still queue in SQLite's lock.
    gate = threading.Lock()

    @event.listens_for(engine, "begin")
    def _on_begin(conn):
        # a deferred reader that later writes can fail with SQLITE_BUSY at once (busy_timeout
        # does not apply to a stale WAL snapshot); writers therefore take the lock up front
        # (on the driver's connection: a statement through SQLAlchemy costs more than BEGIN does)
        driver = conn.connection.driver_connection
        if not conn.get_execution_options().get("write"):
            driver.execute("BEGIN")
            return
        if not gate.acquire(timeout=busy_timeout_ms / 1000):
            raise sqlite3.OperationalError("database is locked (another writer of this process held it too long)")
        try:
            driver.execute("BEGIN IMMEDIATE")
        except BaseException:
            gate.release()
            raise
        conn.info[_GATE_HELD] = True

    @event.listens_for(engine, "commit")
    @event.listens_for(engine, "rollback")
    def _on_end(conn):
        if conn.info.pop(_GATE_HELD, False):
            gate.release()

    @event.listens_for(engine, "checkin")
    @event.listens_for(engine, "invalidate")
    def _on_return(_dbapi_conn, record, *_exc):
        # a connection closed or invalidated mid-transaction (no commit or rollback event)
        if record.info.pop(_GATE_HELD, False):
            gate.release()


@contextmanager
def read_session(engine: Engine) -> Iterator[Session]:
    with Session(engine, expire_on_commit=False) as s:
        yield s


def writer(engine: Engine) -> Session:
    """A session whose transactions are writes (BEGIN IMMEDIATE on SQLite, taken at the first
    statement): use `with s.begin():` around the work, in one thread, so that the write lock
    is held only while the work runs."""
    return Session(write_engine(engine), expire_on_commit=False)


def write_engine(engine: Engine) -> Engine:
    """`engine` whose transactions are writes (BEGIN IMMEDIATE on SQLite, `_on_begin`)."""
    return engine.execution_options(write=True)


@contextmanager
def write_session(engine: Engine) -> Iterator[Session]:
    """One write transaction (BEGIN IMMEDIATE on SQLite): committed on success, rolled back
    on any exception."""
    with writer(engine) as s:
        with s.begin():
            yield s


def ping(engine: Engine) -> None:
    with engine.connect() as c:
        c.execute(text("SELECT 1"))
