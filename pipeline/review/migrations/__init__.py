"""Schema migrations of the review database (Alembic), run by `db.make_engine`.

Inputs: an engine (SQLite or PostgreSQL). Effect: its schema at the newest revision in
`versions/`. A database written before migrations existed (it has `items` but no
`alembic_version`) is the baseline's schema and is stamped so before upgrading; an empty one
is built by the migrations from the start. One upgrader at a time: SQLite's BEGIN IMMEDIATE,
a transaction-level advisory lock on PostgreSQL (`recover review serve --workers N` starts
several processes at once).
"""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from sqlalchemy import inspect, text
from sqlalchemy.engine import Connection, Engine

BASELINE = "0001"  # the schema of the code before migrations (commit b67844a)
_LOCK_KEY = 0x7265_7669  # "revi": the advisory lock migrations take on PostgreSQL


def _config(conn: Connection) -> Config:
    cfg = Config()
    cfg.set_main_option("script_location", str(Path(__file__).resolve().parent))
    cfg.attributes["connection"] = conn
    return cfg


def upgrade(engine: Engine) -> None:
    with engine.execution_options(write=True).begin() as conn:
        if conn.dialect.name == "postgresql":
            conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _LOCK_KEY})
        tables = set(inspect(conn).get_table_names())
        cfg = _config(conn)
        if "items" in tables and "alembic_version" not in tables:
            command.stamp(cfg, BASELINE)
        command.upgrade(cfg, "head")


def current(engine: Engine) -> str | None:
    """The database's revision (None before any)."""
    from alembic.runtime.migration import MigrationContext

    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()
