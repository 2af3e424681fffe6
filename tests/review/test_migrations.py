"""Schema migrations: a database written by the code before them (commit b67844a, the fixture
`data/review_b67844a.sqlite`, made by `data/make_base_fixture.py`) is upgraded in place with
everything in it intact, and the migrations build the schema the models describe."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
import pytest
from sqlalchemy import select, text
from sqlalchemy.exc import DBAPIError

from pipeline.review import migrations, workflow
from pipeline.review.db import Base, User, make_engine, write_session

FIXTURE = Path(__file__).parent / "data" / "review_b67844a.sqlite"
TABLES = ("users", "items", "reviews", "leases", "adjudications", "events")
HEAD = "0005"


def _rows(db: Path) -> dict[str, list[tuple]]:
    con = sqlite3.connect(db)
    try:
        return {t: con.execute(f"SELECT * FROM {t} ORDER BY 1").fetchall() for t in TABLES}
    finally:
        con.close()


def _schema_drift(engine) -> list:
    with engine.connect() as conn:
        return compare_metadata(MigrationContext.configure(conn), Base.metadata)


def test_a_database_of_the_base_commit_is_upgraded_in_place_with_everything_intact(tmp_path):
    db = tmp_path / "review.sqlite"
    shutil.copy(FIXTURE, db)
    before = _rows(db)
    assert [len(before[t]) for t in TABLES] == [4, 6, 7, 1, 1, 23]  # what the fixture holds
    engine = make_engine(f"sqlite:///{db}")  # what `recover review serve` and `stage3` do
    try:
        assert migrations.current(engine) == HEAD
        after = _rows(db)
        # 0003 adds `taken_at` to leases: an old lease counts as taken when it was due to expire
        assert [r[4] for r in after["leases"]] == [r[3] for r in before["leases"]]
        after["leases"] = [r[:4] for r in after["leases"]]
        assert after == before  # every user, item, review, lease, adjudication and audit event
        assert _schema_drift(engine) == []
        # the upgraded queue works: bob's review closes the item ann reviewed and bob holds
        item_id = next(r[0] for r in before["items"] if r[7] == "reviewed")
        with write_session(engine) as s:
            bob = s.scalar(select(User).where(User.name == "bob"))
            workflow.submit_review(s, bob, item_id, {"decision": "accept", "version": 0, "idempotency_key": "b"},
                                   workflow.QueueSettings())
            assert workflow.get_item(s, item_id).status == "final"
    finally:
        engine.dispose()
    engine = make_engine(f"sqlite:///{db}")  # opening it again changes nothing
    assert migrations.current(engine) == HEAD
    engine.dispose()
    con = sqlite3.connect(db)
    assert con.execute("SELECT name FROM sqlite_master WHERE name = 'ix_items_open_queue'").fetchall() == []
    con.close()


def test_the_migrations_build_the_schema_the_models_describe_with_an_append_only_audit_log(engine, items):
    assert migrations.current(engine) == HEAD
    assert _schema_drift(engine) == []
    for stmt in ("UPDATE events SET detail = 'rewritten'", "DELETE FROM events"):
        with pytest.raises(DBAPIError, match="append-only"):
            with write_session(engine) as s:
                s.execute(text(stmt))
