"""The review queue's database: tables and the engine factory.

Inputs: a SQLAlchemy URL (default: SQLite at `<run>/stage3/review.sqlite`).
Outputs: an Engine whose tables exist.
Invariants (enforced by the database, not only by code):
- one review per reviewer per item (`uq_review_item_reviewer`);
- one adjudication per item (`adjudications.item_id` unique);
- one item per (episode key, revision) (`uq_item_key_revision`);
- the audit log is append-only on SQLite (triggers abort UPDATE and DELETE on `events`).
SQLite runs in WAL mode with a busy timeout; write transactions start with
BEGIN IMMEDIATE (use `write_session`) so two writers queue instead of failing on a
lock upgrade. Times are UNIX seconds (float).
"""

from __future__ import annotations

import fcntl
import os
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
    Integer,
    String,
    Text,
    UniqueConstraint,
    create_engine,
    event,
    text,
)
from sqlalchemy.engine import Engine
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column

from pipeline.layout import RunLayout

# item states; "agreed" is passed through on the way to final (recorded as resolution)
PENDING, LEASED, REVIEWED, CONFLICT, ADJUDICATING, FINAL, SUPERSEDED = (
    "pending", "leased", "reviewed", "conflict", "adjudicating", "final", "superseded",
)
COLLECTING = (PENDING, LEASED, REVIEWED)
STATUSES = (PENDING, LEASED, REVIEWED, CONFLICT, ADJUDICATING, FINAL, SUPERSEDED)


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
    status: Mapped[str] = mapped_column(String(16), default=PENDING, index=True)
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


class Lease(Base):
    __tablename__ = "leases"
    __table_args__ = (UniqueConstraint("item_id", "user_id", name="uq_lease_item_user"),)
    id: Mapped[int] = mapped_column(primary_key=True)
    item_id: Mapped[int] = mapped_column(ForeignKey("items.id"), index=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"))
    expires_at: Mapped[float] = mapped_column(Float, index=True)


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


_APPEND_ONLY = [
    "CREATE TRIGGER IF NOT EXISTS events_no_update BEFORE UPDATE ON events "
    "BEGIN SELECT RAISE(ABORT, 'the audit log is append-only'); END",
    "CREATE TRIGGER IF NOT EXISTS events_no_delete BEFORE DELETE ON events "
    "BEGIN SELECT RAISE(ABORT, 'the audit log is append-only'); END",
]


def default_url(run_dir: str | Path) -> str:
    return f"sqlite:///{RunLayout(Path(run_dir).resolve()).stage3.review_db}"


def make_engine(url: str, busy_timeout_ms: int = 10_000) -> Engine:
    """An engine with the tables created; SQLite gets WAL, busy timeout and IMMEDIATE writes."""
    sqlite = url.startswith("sqlite")
    if sqlite and ":memory:" not in url and url.count("/") >= 3:
        path = Path(url.split("///", 1)[1].split("?", 1)[0])
        path.parent.mkdir(parents=True, exist_ok=True)
        _private_files(path)
    kwargs: dict = {"pool_size": 32, "max_overflow": 16} if not sqlite or ":memory:" not in url else {}
    engine = create_engine(url, connect_args={"timeout": busy_timeout_ms / 1000} if sqlite else {}, **kwargs)
    if sqlite:
        _sqlite_setup(engine, busy_timeout_ms)
    Base.metadata.create_all(engine)
    if sqlite:
        with engine.begin() as conn:
            for stmt in _APPEND_ONLY:
                conn.exec_driver_sql(stmt)
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

    @event.listens_for(engine, "begin")
    def _on_begin(conn):
        # a deferred reader that later writes can fail with SQLITE_BUSY at once (busy_timeout
        # does not apply to a stale WAL snapshot); writers therefore take the lock up front
        conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("write") else "BEGIN")


@contextmanager
def read_session(engine: Engine) -> Iterator[Session]:
    with Session(engine, expire_on_commit=False) as s:
        yield s


class _WriterLock:
    """Writers of one SQLite file queue here: a thread lock within the process, then an
    exclusive flock on `<db>.lock` across processes (`recover review serve --workers N`).

    SQLite's own busy handler polls with sleeps of up to 100 ms, which under many concurrent
    writers turns a 5 ms write into a 1 s tail; these locks hand over at once. The busy
    timeout still guards writers that do not take them (other tools)."""

    def __init__(self, path: Path | None):
        self.thread = threading.Lock()
        self.path = path
        self.fd: int | None = None

    def __enter__(self) -> None:
        self.thread.acquire()
        try:
            if self.path is not None:
                if self.fd is None:
                    self.fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o600)
                fcntl.flock(self.fd, fcntl.LOCK_EX)
        except BaseException:
            self.thread.release()
            raise

    def __exit__(self, *exc) -> None:
        try:
            if self.fd is not None:
                fcntl.flock(self.fd, fcntl.LOCK_UN)
        finally:
            self.thread.release()


_WRITE_LOCKS: dict[tuple[int, str], _WriterLock] = {}
_WRITE_LOCKS_GUARD = threading.Lock()


def _writer_lock(engine: Engine) -> _WriterLock | None:
    if engine.dialect.name != "sqlite":
        return None
    with _WRITE_LOCKS_GUARD:
        key = (id(engine), str(engine.url))  # the URL too: an id may be reused by a later engine
        lock = _WRITE_LOCKS.get(key)
        if lock is None:
            db = engine.url.database
            path = Path(db).with_name(Path(db).name + ".lock") if db and db != ":memory:" else None
            lock = _WRITE_LOCKS[key] = _WriterLock(path)
        return lock


@contextmanager
def write_session(engine: Engine) -> Iterator[Session]:
    """One write transaction (BEGIN IMMEDIATE): committed on success, rolled back on any
    exception; on SQLite taken under the file's writer lock (`_WriterLock`)."""
    lock = _writer_lock(engine)
    if lock is not None:
        lock.__enter__()
    try:
        with Session(engine.execution_options(write=True), expire_on_commit=False) as s:
            with s.begin():
                yield s
    finally:
        if lock is not None:
            lock.__exit__(None, None, None)


def ping(engine: Engine) -> None:
    with engine.connect() as c:
        c.execute(text("SELECT 1"))
