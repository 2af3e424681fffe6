"""Reviewers deciding the same items at the same time, against the real server and SQLite."""

from __future__ import annotations

import threading

import httpx
from sqlalchemy import func, select

from pipeline.review.db import Item, Review, User, read_session


def _stored(engine) -> dict[tuple[int, str], str]:
    with read_session(engine) as s:
        rows = s.execute(select(Review.item_id, User.name, Review.decision)
                         .join(User, User.id == Review.reviewer_id)).all()
    return {(i, n): d for i, n, d in rows}


def test_concurrent_reviewers_lose_no_decision_and_never_exceed_k(server, engine, people, items):
    names = ["ann", "bob", "cat"]  # three people racing for K = 2 places on every item
    barrier = threading.Barrier(len(names))
    results: dict[str, list[tuple[int, int, dict]]] = {n: [] for n in names}

    def reviewer(name: str) -> None:
        with httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {people[name]}"}, timeout=30) as c:
            for item_id in items:
                barrier.wait()
                body = {"decision": "revise", "version": 0, "idempotency_key": f"{name}-{item_id}",
                        "fields": {"fail_time_s": 1.0, "recovery_level": "L1", "failure_category": "grasp_failure",
                                   "recovery_action": f"retry ({name})"}}
                r = c.post(f"/api/items/{item_id}/review", json=body)
                results[name].append((item_id, r.status_code, r.json()))
                # the same decision again at once (a double click) must change nothing
                r2 = c.post(f"/api/items/{item_id}/review", json=body)
                if r.status_code == 200:
                    assert r2.status_code == 200 and r2.json()["replayed"] is True

    threads = [threading.Thread(target=reviewer, args=(n,)) for n in names]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert not any(t.is_alive() for t in threads)

    stored = _stored(engine)
    accepted = {(i, n) for n in names for i, code, _ in results[n] if code == 200}
    refused = [(i, n, body) for n in names for i, code, body in results[n] if code != 200]
    assert accepted == set(stored)  # every acknowledged decision is in the database, nothing else
    assert all(code in (200, 409) for n in names for _, code, _ in results[n])
    assert all("reviews" in body["detail"] for _, _, body in refused)
    with read_session(engine) as s:
        per_item = dict(s.execute(select(Review.item_id, func.count()).group_by(Review.item_id)).all())
        n_reviews = dict(s.execute(select(Item.id, Item.n_reviews)).all())
    assert per_item == {i: 2 for i in items}
    assert n_reviews == per_item
    assert len(refused) == len(items)


def test_two_reviewers_pulling_from_the_queue_at_once_share_items_up_to_k(server, engine, people, items):
    decided: dict[str, list[int]] = {"ann": [], "bob": []}

    def work(name: str) -> None:
        with httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {people[name]}"}, timeout=30) as c:
            while True:
                nxt = c.post("/api/queue/next").json()["item"]
                if nxt is None:
                    return
                body = {"decision": "flag", "reason": "race", "version": 0, "idempotency_key": f"{name}-{nxt}"}
                r = c.post(f"/api/items/{nxt}/review", json=body)
                assert r.status_code == 200, r.text
                decided[name].append(nxt)

    threads = [threading.Thread(target=work, args=(n,)) for n in decided]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    # with K = 2 and two reviewers, each of them reviews every item exactly once
    assert sorted(decided["ann"]) == sorted(items) == sorted(decided["bob"])
    assert len(_stored(engine)) == 2 * len(items)


def test_one_reviewer_sending_two_different_first_decisions_at_once_stores_one(engine, settings, people, items):
    # each starts with no review of theirs; inside its write transaction (the item's row lock
    # on PostgreSQL) the later ones find the first and are a repeat or a stale edit, never a
    # second review
    from pipeline.review import workflow
    from pipeline.review.db import write_session
    from pipeline.review.errors import Stale

    with read_session(engine) as s:
        ann = s.scalar(select(User).where(User.name == "ann"))
    barrier = threading.Barrier(8)
    outcomes: list[str] = []

    def send(i: int) -> None:
        body = {"decision": "revise", "version": 0, "idempotency_key": f"k{i}",
                "fields": {"recovery_level": f"L{1 + i % 2}"}}
        barrier.wait()
        try:
            with write_session(engine) as s:
                _review, replayed = workflow.submit_review(s, ann, items[0], body, settings)
            outcomes.append("replayed" if replayed else "stored")
        except Stale:
            outcomes.append("stale")

    threads = [threading.Thread(target=send, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    with read_session(engine) as s:
        assert s.scalar(select(func.count(Review.id)).where(Review.item_id == items[0])) == 1
        assert s.scalar(select(Item.n_reviews).where(Item.id == items[0])) == 1
    assert outcomes.count("stored") == 1 and len(outcomes) == 8


def test_the_writer_gate_is_freed_by_commit_rollback_and_a_failed_begin(tmp_path):
    """SQLite writers of one process queue on the engine's gate (`db._sqlite_setup`); a write
    that fails, or whose BEGIN IMMEDIATE fails, must not keep it (the next writer would wait
    the whole busy timeout and fail)."""
    import sqlite3
    import time

    import pytest
    from sqlalchemy import text

    from pipeline.review.db import make_engine, write_session

    url = f"sqlite:///{tmp_path / 'review.sqlite'}"
    engine = make_engine(url, busy_timeout_ms=300)
    with pytest.raises(RuntimeError):
        with write_session(engine) as s:
            s.execute(text("SELECT 1"))
            raise RuntimeError("a rule refused the write")
    other = sqlite3.connect(tmp_path / "review.sqlite", isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # another process holds SQLite's write lock
    with pytest.raises(Exception, match="locked"):
        with write_session(engine) as s:
            s.execute(text("SELECT 1"))
    other.execute("COMMIT")
    t0 = time.perf_counter()
    for _ in range(3):
        with write_session(engine) as s:
            s.execute(text("SELECT 1"))
    assert time.perf_counter() - t0 < 0.25  # none waited out the 0.3 s gate timeout
    other.close()
    engine.dispose()


def test_a_pooled_postgresql_connection_killed_while_idle_is_replaced_before_use(pg_cluster):
    """A team's server restarts while the review server idles: the next request still works
    (the pool pings a connection before handing it out; PostgreSQL only, SQLite has no server)."""
    from sqlalchemy import text

    from pipeline.review import db

    url = pg_cluster.new_database()
    engine = db.make_engine(url)
    try:
        db.ping(engine)  # a connection now sits in the pool
        pg_cluster._admin("SELECT pg_terminate_backend(pid) FROM pg_stat_activity "
                          f"WHERE datname = '{engine.url.database}' AND pid <> pg_backend_pid()")
        with engine.connect() as c:
            assert c.execute(text("SELECT 1")).scalar() == 1
    finally:
        engine.dispose()
        pg_cluster.drop_database(url)
