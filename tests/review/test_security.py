"""Issue 12: blindness of open items, private database files, API docs, reviewer management."""

from __future__ import annotations

import os
import stat
import subprocess

import httpx
import yaml

from pipeline.review.api import create_app
from pipeline.review.auth import list_users, set_active
from pipeline.review.db import make_engine
from pipeline.review.server import ThreadedServer
from tests.review.test_api import accept, client


def test_an_adjudicator_cannot_read_the_reviews_of_an_open_item(server, people, items):
    ann, dan, eve = (client(server, people, n) for n in ("ann", "dan", "eve"))
    assert accept(ann, items[0]).status_code == 200  # one of two reviews: still collecting
    for who in (dan, eve):
        for path in (f"/api/items/{items[0]}/adjudication", f"/api/items/{items[0]}/history"):
            r = who.get(path)
            assert r.status_code == 403 and "still being collected" in r.json()["detail"], (path, r.text)


def test_whoever_read_an_items_reviews_can_no_longer_review_it(server, people, items, engine):
    ann, bob, dan = (client(server, people, n) for n in ("ann", "bob", "dan"))
    accept(ann, items[1])
    bob.post(f"/api/items/{items[1]}/review", json={"decision": "revise", "version": 0, "idempotency_key": "b",
                                                   "fields": {"failure_category": "grasp_failure"}})
    assert dan.get(f"/api/items/{items[1]}/adjudication").status_code == 200  # closed: in conflict
    # a new revision of the same episode opens for review: dan has read its reviews
    from pipeline.review.db import Item, write_session
    from pipeline.review.enqueue import enqueue

    with write_session(engine) as s:
        old = s.get(Item, items[1])
        proposal = {**old.proposal, "recovery_action": "Lift the bowl and put it back on the plate"}
        new, _ = enqueue(s, key=old.key, instruction=old.instruction, proposal=proposal, context=old.context,
                         required_reviews=2, quarantined=False, reason=None)
        new_id = new.id
    assert new_id != items[1]
    r = accept(dan, new_id, key="d")
    assert r.status_code == 409 and "read the reviews" in r.json()["detail"]
    assert dan.post(f"/api/items/{new_id}/lease").status_code == 409
    seen = set()
    while (nxt := dan.post("/api/queue/next").json()["item"]) is not None and nxt not in seen:
        seen.add(nxt)
        accept(dan, nxt, key=f"q{nxt}")
    assert new_id not in seen


def test_the_database_and_its_wal_are_created_owner_only(tmp_path):
    db = tmp_path / "stage3" / "review.sqlite"
    engine = make_engine(f"sqlite:///{db}")
    try:
        from pipeline.review.auth import add_user

        add_user(engine, "ann", "reviewer")  # a write: the -wal and -shm files exist now
        files = [p for p in (db, db.with_name("review.sqlite-wal"), db.with_name("review.sqlite-shm")) if p.exists()]
        assert len(files) == 3
        for p in files:
            assert stat.S_IMODE(p.stat().st_mode) == 0o600, p
    finally:
        engine.dispose()


def test_an_existing_world_readable_database_is_tightened(tmp_path):
    db = tmp_path / "review.sqlite"
    make_engine(f"sqlite:///{db}").dispose()
    os.chmod(db, 0o644)
    make_engine(f"sqlite:///{db}").dispose()
    assert stat.S_IMODE(db.stat().st_mode) == 0o600


def test_api_docs_are_off_by_default_and_behind_sign_in_when_on(run_dir, engine, settings, people, items):
    for docs in (False, True):
        with ThreadedServer(create_app(run_dir, engine, settings, docs=docs)) as srv:
            for path in ("/api/docs", "/api/openapi.json"):
                anon = httpx.get(srv.url + path)
                assert anon.status_code in (401, 404), (docs, path, anon.status_code)
                assert "openapi" not in anon.text.lower() or anon.status_code == 401
                signed_in = client(srv, people, "ann").get(path)
                assert signed_in.status_code == (200 if docs else 404), (docs, path)
            if docs:
                paths = client(srv, people, "ann").get("/api/openapi.json").json()["paths"]
                assert "/api/items/{item_id}/review" in paths


def test_a_deactivated_reviewers_token_is_refused_until_reactivated(server, people, engine):
    ann = client(server, people, "ann")
    assert ann.get("/api/me").status_code == 200
    assert set_active(engine, "ann", False) is True
    assert ann.get("/api/me").status_code == 401
    assert httpx.post(server.url + "/api/login", json={"token": people["ann"]}).status_code == 401
    assert {u["name"]: u["active"] for u in list_users(engine)}["ann"] is False
    assert set_active(engine, "ann", True) is True and ann.get("/api/me").status_code == 200


def test_recover_review_reviewers_lists_deactivates_and_reactivates(tmp_path):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(tmp_path / "run")}}))
    from tests.cli.test_tasks_command import RECOVER

    recover = [RECOVER]

    def run(*args):
        return subprocess.run([*recover, "review", *args, "-c", str(cfg)], capture_output=True, text=True, timeout=120)

    assert run("add-reviewer", "ann").returncode == 0
    assert "ann" in run("reviewers", "list").stdout
    out = run("reviewers", "deactivate", "ann")
    assert out.returncode == 0 and "deactivated" in out.stdout
    assert " no " in run("reviewers", "list").stdout.replace("│", " ")
    assert run("reviewers", "reactivate", "ann").returncode == 0
    missing = run("reviewers", "deactivate", "nobody")
    assert missing.returncode == 2 and "no reviewer named 'nobody'" in missing.stderr
