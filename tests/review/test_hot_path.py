"""The requests of every reviewed item: the fast reads answer as the ORM views, run no ORM
statement once warm, and anything unusual still gets FastAPI's answer."""

from __future__ import annotations

import json

import httpx
import pytest
from sqlalchemy import event, select

from pipeline.review import fastread, views, workflow
from pipeline.review.db import Item, User, read_session


def client(server, people, name: str) -> httpx.Client:
    return httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {people[name]}"}, timeout=10)


def decide(c: httpx.Client, item_id: int, key: str, level: str = "L2", **kw) -> httpx.Response:
    return c.post(f"/api/items/{item_id}/review", json={"decision": "revise", "version": 0, "idempotency_key": key,
                                                        "fields": {"recovery_level": level}}, **kw)


def _both(engine, item_id: int, name: str) -> tuple[dict, dict]:
    with read_session(engine) as s:
        user = s.scalar(select(User).where(User.name == name))
        orm = views.reviewer_view(s, workflow.get_item(s, item_id), user)
    return json.loads(fastread.reviewer_view_json(engine, item_id, user)), orm


def test_the_fast_item_view_is_the_orm_view_in_every_state(server, people, items, engine):
    ann, bob = client(server, people, "ann"), client(server, people, "bob")
    item = items[0]
    fast, orm = _both(engine, item, "ann")  # untouched
    assert fast == orm and fast["my_review"] is None and fast["lease_expires_at"] is None
    assert ann.post("/api/queue/next").json()["item"] == item
    fast, orm = _both(engine, item, "ann")  # leased by ann
    assert fast == orm and fast["lease_expires_at"] is not None
    assert decide(ann, item, "a").status_code == 200
    fast, orm = _both(engine, item, "ann")  # ann's review in, still open
    assert fast == orm and fast["my_review"]["values"]["recovery_level"] == "L2" and fast["state"] == "open"
    assert bob.post("/api/queue/next").json()["item"] == item
    assert decide(bob, item, "b", "L4").status_code == 200
    for name in ("ann", "bob", "cat"):  # closed (a conflict), seen by each
        fast, orm = _both(engine, item, name)
        assert fast == orm and fast["state"] == "closed"


def test_a_reviewed_item_runs_no_orm_statement_once_warm(server, people, items, engine, monkeypatch):
    monkeypatch.setattr(workflow, "SWEEP_EVERY_S", 3600.0)  # the periodic sweep is the general path
    statements: list[str] = []
    ann = client(server, people, "ann")

    def one_item(key: str) -> int:
        item = ann.post("/api/queue/next").json()["item"]
        for path in ("", "/frames", "/evidence"):
            assert ann.get(f"/api/items/{item}{path}").status_code == 200
        assert decide(ann, item, key).status_code == 200
        return item

    one_item("warm")  # first sweep, statements compiled, the shared tables loaded
    def seen(_conn, _cursor, statement, *_rest):
        statements.append(statement)

    event.listen(engine, "before_cursor_execute", seen)
    try:
        one_item("hot")
    finally:
        event.remove(engine, "before_cursor_execute", seen)
    assert statements == [], statements  # every statement went straight to the DBAPI cursor (rawsql)


@pytest.mark.parametrize("case", ["text_body", "bad_field", "not_json", "big_body"])
def test_an_unusual_decision_request_gets_fastapis_answer(server, people, items, engine, case):
    ann = client(server, people, "ann")
    item = ann.post("/api/queue/next").json()["item"]
    body = {"decision": "revise", "version": 0, "idempotency_key": "k", "fields": {"recovery_level": "L9"}}
    if case == "text_body":  # FastAPI reads a JSON body sent as text/plain as bytes: 422 on the body
        r = ann.post(f"/api/items/{item}/review", content=json.dumps({**body, "fields": {"recovery_level": "L2"}}),
                     headers={"Content-Type": "text/plain"})
        assert r.status_code == 422
    elif case == "bad_field":
        r = ann.post(f"/api/items/{item}/review", json=body)
        assert r.status_code == 422 and r.json()["field"] == "recovery_level"
    elif case == "not_json":
        r = ann.post(f"/api/items/{item}/review", content=b"{not json", headers={"Content-Type": "application/json"})
        assert r.status_code == 422 and "detail" in r.json()
    else:  # over the lane's 64 KiB: FastAPI reads the rest and names the field
        r = ann.post(f"/api/items/{item}/review", json={**body, "reason": "x" * 70_000})
        assert r.status_code == 422 and r.json()["field"] in ("reason", "recovery_level")
    assert r.headers["x-content-type-options"] == "nosniff"
    with read_session(engine) as s:
        assert s.get(Item, item).n_reviews == 0


def test_a_write_that_finds_the_lock_held_waits_in_a_thread_and_is_stored_once(server, people, items, engine, settings):
    # the event loop writes only when the writer lock is free; held, the write goes to a
    # thread and waits (Busy leaves nothing behind, so it starts again from the beginning)
    import threading
    import time

    from pipeline.review import fastwrite, rawsql
    from pipeline.review.db import Review, writer_lock

    ann = client(server, people, "ann")
    item = ann.post("/api/queue/next").json()["item"]
    lock = writer_lock(engine)
    with read_session(engine) as s:
        user = s.scalar(select(User).where(User.name == "ann"))
    body = {"decision": "revise", "version": 0, "idempotency_key": "busy", "fields": {"recovery_level": "L2"}}
    with lock:
        assert not lock.try_enter()
        with pytest.raises(rawsql.Busy):
            fastwrite.decide(engine, user, item, body, settings, wait=False)
        done: list[httpx.Response] = []
        t = threading.Thread(target=lambda: done.append(decide(ann, item, "busy")))
        t.start()
        time.sleep(0.3)
        assert done == []  # waiting for the lock, not refused
    t.join(timeout=10)
    assert done[0].status_code == 200 and done[0].json()["replayed"] is False
    with read_session(engine) as s:
        assert s.scalars(select(Review.idempotency_key).where(Review.item_id == item)).all() == ["busy"]



def test_the_next_item_search_walks_the_open_queue_index_without_sorting(engine, items):
    # with every open item sorted for every queue/next, its cost grew with the queue
    # (5.7 ms at 3000 open items); walking the open-queue index it stops after a few
    from pipeline.review import fastwrite, rawsql

    c = fastwrite._CANDIDATES.compiled(engine.dialect)
    with rawsql.reading(engine) as cur:
        cur.cur.execute("EXPLAIN QUERY PLAN " + c.sql, c.params({"n": 8, "uid": 1, "t": 0.0, "uname": "ann"}))
        plan = " | ".join(str(r[-1]) for r in cur.cur.fetchall())
    assert "ix_items_open_queue" in plan and "ORDER BY" not in plan, plan
