"""Prebuilt Core statements run straight on a pooled DBAPI cursor (the review's hot paths).

Inputs: a SQLAlchemy Core statement (built once, at import), an engine, parameters by name.
Outputs: rows as named tuples, with the columns' own type conversions (JSON decoded,
booleans as bool), and parameters converted as SQLAlchemy would (JSON encoded).
Why: with 20 reviewers on 2 cores the server is CPU-bound. An ORM session and query cost
about 0.2 ms and a Core `conn.execute` about 0.05 ms, the same compiled statement on a
DBAPI cursor about 0.005 ms; each reviewer's item runs a dozen of them.
Invariants: statements are compiled once per dialect (any SQLAlchemy database works, not
only SQLite); every bound name must be given (a missing one raises, it never becomes NULL);
`writing` holds the same writer lock and BEGIN IMMEDIATE as `db.write_session`.
"""

from __future__ import annotations

import threading
from collections import namedtuple
from collections.abc import Iterator
from contextlib import contextmanager

from sqlalchemy import bindparam
from sqlalchemy.engine import Engine

from pipeline.review.db import writer_lock


def param(name: str):
    """A named parameter of a prebuilt statement (no value: `Cursor` requires one per call)."""
    return bindparam(name, None)


class _Compiled:
    def __init__(self, stmt, dialect, edit=None):
        c = stmt.compile(dialect=dialect, compile_kwargs={"render_postcompile": True})
        self.sql = edit(c.string) if edit is not None else c.string
        self.defaults = dict(c.params)  # literal values (IN lists, `+ 1`) and our named params
        self.required = {k for k, v in self.defaults.items() if v is None}
        self.order = tuple(c.positiontup) if c.positional else None
        self.binds = dict(c._bind_processors)
        cols = c._result_columns
        self.procs = [e.type._cached_result_processor(dialect, None) for e in cols]
        self.any_proc = any(self.procs)
        self.row = namedtuple("Row", [e.keyname for e in cols], rename=True) if cols else None

    def params(self, given: dict):
        missing = self.required - given.keys()
        if missing:
            raise TypeError(f"statement needs parameter(s) {sorted(missing)}: {self.sql[:80]}")
        p = {**self.defaults, **given}
        for k, f in self.binds.items():
            p[k] = f(p[k])
        return tuple(p[k] for k in self.order) if self.order is not None else p

    def rows(self, raw: list) -> list:
        if self.any_proc:
            procs = self.procs
            raw = [[v if f is None else f(v) for f, v in zip(procs, r)] for r in raw]
        return [self.row._make(r) for r in raw]


class Stmt:
    """A Core statement compiled lazily, once per dialect."""

    def __init__(self, stmt, sqlite_edit=None):
        self.stmt = stmt
        self.sqlite_edit = sqlite_edit  # a change of the SQL text on SQLite (an index hint)
        self._compiled: dict[str, _Compiled] = {}
        self._lock = threading.Lock()

    def compiled(self, dialect) -> _Compiled:
        c = self._compiled.get(dialect.name)
        if c is None:
            with self._lock:
                edit = self.sqlite_edit if dialect.name == "sqlite" else None
                c = self._compiled.setdefault(dialect.name, _Compiled(self.stmt, dialect, edit))
        return c


class Cursor:
    def __init__(self, cur, dialect):
        self.cur, self.dialect = cur, dialect

    def all(self, st: Stmt, **params) -> list:
        c = st.compiled(self.dialect)
        self.cur.execute(c.sql, c.params(params))
        # rows of an UPDATE ... RETURNING are read at once: the statement completes with them
        return c.rows(self.cur.fetchall()) if c.row is not None else []

    def first(self, st: Stmt, **params):
        rows = self.all(st, **params)
        return rows[0] if rows else None

    def run(self, st: Stmt, **params) -> int:
        """A statement without result rows; returns the row count."""
        c = st.compiled(self.dialect)
        self.cur.execute(c.sql, c.params(params))
        return self.cur.rowcount


@contextmanager
def reading(engine: Engine) -> Iterator[Cursor]:
    """A pooled connection for reads (on SQLite each statement is its own snapshot: put what
    must agree in one statement)."""
    conn = engine.raw_connection()
    cur = conn.cursor()
    try:
        yield Cursor(cur, engine.dialect)
    finally:
        cur.close()
        conn.close()  # back to the pool, which rolls back whatever is open


class Busy(Exception):
    """The writer lock is held by someone else (`writing(wait=False)`): nothing was done."""


@contextmanager
def writing(engine: Engine, wait: bool = True) -> Iterator[Cursor]:
    """One write transaction, committed on success and rolled back on any exception, under
    the database's writer lock (as `db.write_session`); `wait=False`: `Busy` if it is held."""
    lock = writer_lock(engine)
    if lock is not None:
        if wait:
            lock.__enter__()
        elif not lock.try_enter():
            raise Busy("the writer lock is held")
    try:
        conn = engine.raw_connection()
        cur = conn.cursor()
        try:
            if engine.dialect.name == "sqlite":
                cur.execute("BEGIN IMMEDIATE")
            yield Cursor(cur, engine.dialect)
            conn.commit()
        except BaseException:
            conn.rollback()
            raise
        finally:
            cur.close()
            conn.close()
    finally:
        if lock is not None:
            lock.__exit__(None, None, None)
