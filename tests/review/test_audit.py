"""The audit log: append-only in the database, complete per item."""

from __future__ import annotations

import pytest
from sqlalchemy import delete, select, update
from sqlalchemy.exc import DatabaseError

from pipeline.review import audit, workflow
from pipeline.review.db import Event, User, read_session, write_session


def test_the_database_refuses_to_change_or_delete_audit_events(engine, items):
    with pytest.raises(DatabaseError, match="append-only"):
        with write_session(engine) as s:
            s.execute(update(Event).values(actor="mallory"))
    with pytest.raises(DatabaseError, match="append-only"):
        with write_session(engine) as s:
            s.execute(delete(Event))
    with read_session(engine) as s:
        assert {e.actor for e in s.scalars(select(Event).where(Event.kind == "enqueued"))} == {"stage3"}


def test_history_shows_who_when_before_after_and_the_model_version(engine, people, items, settings):
    with read_session(engine) as s:
        ann = s.scalar(select(User).where(User.name == "ann"))
    with write_session(engine) as s:
        workflow.submit_review(s, ann, items[0], {"decision": "accept", "idempotency_key": "a"}, settings)
    with write_session(engine) as s:
        workflow.submit_review(s, ann, items[0], {"decision": "revise", "fields": {"recovery_level": "L2"},
                                                  "version": 1, "idempotency_key": "b"}, settings)
    with read_session(engine) as s:
        events = audit.history(s, items[0])
        by_key = audit.history(s, s.get(workflow.Item, items[0]).key)
    assert events == by_key
    kinds = [e["kind"] for e in events]
    assert kinds == ["enqueued", "review", "review_changed"]
    changed = events[-1]
    assert changed["actor"] == "ann" and changed["at"].endswith("+00:00")
    assert changed["before"]["decision"] == "accept" and changed["after"]["values"]["recovery_level"] == "L2"
    assert changed["model"] == "simstate"


def test_a_rejected_write_leaves_no_event(engine, people, items, settings):
    with read_session(engine) as s:
        ann = s.scalar(select(User).where(User.name == "ann"))
        before = len(audit.history(s, items[0]))
    with pytest.raises(workflow.Invalid):
        with write_session(engine) as s:
            workflow.submit_review(s, ann, items[0], {"decision": "revise", "fields": {"recovery_level": "L9"},
                                                      "idempotency_key": "x"}, settings)
    with read_session(engine) as s:
        assert len(audit.history(s, items[0])) == before
