"""Issue 29's probe findings as real requests against a real server (uvicorn on loopback,
SQLite and PostgreSQL), one test per finding: the generator's truth and the logged steps are
never served (1); nobody reads an episode's reviews while any revision of it is collecting,
nor changes a review after reading them (2); oversized or slow requests are refused before
anyone is authenticated or anything parsed (3); the status counts no agreement of items
still collecting (4); hostile JSON and out-of-range ids are 4xx, never 500 (5); an admin
who reviewed an item does not read its other decisions (6); CLI tables print names and
rationales literally (7); request fields are never coerced (8); failed sign-ins are logged
and throttled, leases capped per person and never renewed past their lifetime (9). Last, a
fuzz test over the write endpoints' bodies: never a 500, no change on a refused request."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path

import httpx
import pytest
import yaml
from sqlalchemy import select, text, update

from pipeline.review.db import Event, Item, Lease, read_session, write_session
from tests.review.test_api import accept, client

ITEM_ROUTES = [("GET", ""), ("POST", "/lease"), ("POST", "/review"), ("GET", "/evidence"), ("GET", "/frames"),
               ("GET", "/adjudication"), ("POST", "/claim"), ("POST", "/adjudication"), ("GET", "/history")]


def test_only_the_videos_items_show_are_served_never_the_truth_or_the_logs(server, people, items, run_dir):
    ann = client(server, people, "ann")
    video = ann.get(f"/api/items/{items[0]}").json()["media"]["videos"]["agentview"]
    assert ann.get(video).status_code == 200
    folder = Path(video.removeprefix("/media/")).parent
    (run_dir / folder / "truth.parquet").write_bytes(b"PAR1 the generator's onset PAR1")  # as stage 1 writes it
    for name in ("truth.parquet", "steps.parquet", "frames.parquet", "../episodes.parquet"):
        r = ann.get(f"/media/{folder}/{name}")
        assert r.status_code == 404 and b"onset" not in r.content, (name, r.status_code)
    # the frame and evidence tables go through their own routes, for items only
    assert ann.get(f"/api/items/{items[0]}/frames").status_code == 200


def test_an_oversized_body_is_refused_before_authentication_and_parsing(server, people, items, engine):
    url = f"{server.url}/api/items/{items[0]}/review"
    big = b'{"decision": "' + b"x" * 2_000_000 + b'"}'
    for headers in ({}, {"Authorization": f"Bearer {people['ann']}"}):  # by its length, whoever sends it
        r = httpx.post(url, content=big, headers={"content-type": "application/json", **headers})
        assert r.status_code == 413
    # without credentials the body is never read: 401, even chunked and nested 10,000 deep
    r = httpx.post(url, content=iter([b"[" * 10_000] * 20), headers={"content-type": "application/json"})
    assert r.status_code == 401
    # sent in chunks, without a length, by someone signed in: refused once it passes the limit
    r = client(server, people, "ann").post(f"/api/items/{items[0]}/review", content=iter([b"[" * 10_000] * 20),
                                           headers={"content-type": "application/json"})
    assert r.status_code == 413
    from pipeline.review.db import Item, read_session

    with read_session(engine) as s:
        assert s.get(Item, items[0]).n_reviews == 0


def test_oversized_headers_are_refused(server):
    r = httpx.get(f"{server.url}/api/me", headers={"x-filler": "y" * 20_000})
    assert r.status_code == 431
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:  # many small headers
        sock.sendall(b"GET /api/me HTTP/1.1\r\nHost: x\r\n" + b"".join(b"x-h%d: %s\r\n" % (i, b"z" * 100)
                                                                       for i in range(300)) + b"\r\n")
        assert sock.recv(64).split(b" ")[1] == b"431"


def test_hostile_json_and_out_of_range_ids_are_4xx_never_500(server, people, items):
    ann, dan = client(server, people, "ann"), client(server, people, "dan")
    deep = b'{"decision": ' + b"[" * 1000 + b"]" * 1000 + b"}"
    for who, path in ((ann, f"/api/items/{items[0]}/review"), (dan, f"/api/items/{items[0]}/adjudication")):
        r = who.post(path, content=deep, headers={"content-type": "application/json"})
        assert r.status_code == 422, (path, r.status_code, r.text[:200])
    r = httpx.post(f"{server.url}/api/login", content=b'{"token": ' + b"[" * 1000 + b"]" * 1000 + b"}",
                   headers={"content-type": "application/json"})
    assert r.status_code == 422
    bodies = {"/review": {"decision": "accept", "version": 0, "idempotency_key": "k"},
              "/adjudication": {"version": 0, "idempotency_key": "k", "rationale": "r"}}
    for huge in (2**31, 2**63, 2**64 + 1, -1, 0):
        for method, tail in ITEM_ROUTES:
            r = dan.request(method, f"/api/items/{huge}{tail}", json=bodies.get(tail) if method == "POST" else None)
            assert r.status_code == 422 and "item_id" in {e["field"] for e in r.json()["errors"]}, (huge, tail)
    assert ann.get(f"/api/items/{2**31 - 1}").status_code == 404  # in range, no such item


@pytest.mark.parametrize("content", [b"not json", b'"a string"', b"[]", b'{"decision": "accept", "version": 0}',
                                     b'{"decision": "accept", "version": 0, "idempotency_key": "k"} as text/plain'])
def test_a_malformed_decision_changes_nothing(server, people, items, engine, content):
    from pipeline.review.db import Item, read_session

    content, _, kind = content.partition(b" as ")  # a well-formed decision, but not sent as JSON
    r = client(server, people, "ann").post(f"/api/items/{items[0]}/review", content=content,
                                           headers={"content-type": (kind or b"application/json").decode()})
    assert r.status_code == 422 and "detail" in r.json()
    with read_session(engine) as s:
        assert s.get(Item, items[0]).n_reviews == 0


def _revise(c: httpx.Client, item_id: int, key: str, version: int = 0, **fields) -> httpx.Response:
    return c.post(f"/api/items/{item_id}/review", json={"decision": "revise", "version": version,
                                                        "idempotency_key": key, "fields": fields})


def _new_revision(engine, item_id: int) -> int:
    """Stage 3 enqueues a new proposal for the episode of `item_id`: its next revision."""
    from pipeline.review.enqueue import enqueue

    with write_session(engine) as s:
        old = s.get(Item, item_id)
        new, _ = enqueue(s, key=old.key, instruction=old.instruction, context=old.context, required_reviews=2,
                         proposal={**old.proposal, "recovery_action": "Lift the bowl and put it back on the plate"})
        return new.id


def test_no_review_of_an_episode_is_read_while_a_revision_is_collecting_nor_changed_after_reading(
        server, people, items, engine):
    ann, bob, dan = (client(server, people, n) for n in ("ann", "bob", "dan"))
    assert accept(ann, items[0]).status_code == 200 and accept(bob, items[0]).status_code == 200  # revision 1: final
    rev2 = _new_revision(engine, items[0])
    assert accept(dan, rev2, key="d").status_code == 200  # dan's open review of revision 2
    for path in (f"/api/items/{items[0]}/adjudication", f"/api/items/{items[0]}/history",
                 f"/api/items/{rev2}/history"):
        r = dan.get(path)
        assert r.status_code == 403 and "still being collected" in r.json()["detail"], (path, r.status_code)
    r = _revise(dan, rev2, "d2", version=1, failure_category="grasp_failure")
    assert r.status_code == 200  # he read nothing, so he may still change his own review
    # had he read them (an older server let him), no change to his review is taken any more
    from pipeline.review import audit, blindness

    with write_session(engine) as s:
        audit.record(s, "dan", blindness.READ_REVIEWS, s.get(Item, items[0]))
    r = _revise(dan, rev2, "d3", version=2, failure_category="placement_failure")
    assert r.status_code == 409 and "read the reviews" in r.json()["detail"]
    assert dan.post(f"/api/items/{rev2}/lease").status_code == 409


def test_the_status_counts_no_agreement_of_items_still_collecting(server, people, items, engine):
    with write_session(engine) as s:  # K = 3
        s.execute(update(Item).values(required_reviews=3))
    ann, bob, cat, dan = (client(server, people, n) for n in ("ann", "bob", "cat", "dan"))
    assert accept(ann, items[0]).status_code == 200
    assert _revise(bob, items[0], "b", failure_category="grasp_failure").status_code == 200
    agreement = dan.get("/api/status").json()["agreement"]
    assert agreement["items"] == 0 and agreement["failure_category"]["percent_agreement"] is None
    assert accept(cat, items[0], key="c").status_code == 200  # the third review closes it
    agreement = dan.get("/api/status").json()["agreement"]
    assert agreement["items"] == 1 and agreement["failure_category"]["percent_agreement"] == 0.0
    for who in (ann, bob, cat):  # a second item, final: all three agree
        assert accept(who, items[1], key="f").status_code == 200
    assert dan.get("/api/status").json()["agreement"]["items"] == 2
    _new_revision(engine, items[1])  # its episode collects again: its reviews count nowhere until that closes
    assert dan.get("/api/status").json()["agreement"]["items"] == 1


def test_an_admin_who_reviewed_an_item_reads_none_of_its_other_decisions(server, people, items):
    ann, eve = client(server, people, "ann"), client(server, people, "eve")
    assert accept(eve, items[0], key="e").status_code == 200
    assert _revise(ann, items[0], "a", failure_category="grasp_failure").status_code == 200  # closed: conflict
    for path in ("adjudication", "history"):
        r = eve.get(f"/api/items/{items[0]}/{path}")
        assert r.status_code == 403 and "you reviewed" in r.json()["detail"], (path, r.status_code)
        assert "grasp_failure" not in r.text
    assert client(server, people, "dan").get(f"/api/items/{items[0]}/history").status_code == 200


def test_cli_tables_print_names_and_rationales_literally(server, people, items, run_dir, db_url, engine, tmp_path):
    from typer.testing import CliRunner

    from pipeline.review.auth import add_user
    from pipeline.review.cli import app

    hostile = "[bold]x[/bold]\x1b[2J\x1b]0;owned\x07\x1b]8;;http://evil/\x1b\\link\x1b]8;;\x1b\\\r\u202e"
    add_user(engine, "[red]mal\x1b[8m", "reviewer")
    ann, bob, dan = (client(server, people, n) for n in ("ann", "bob", "dan"))
    accept(ann, items[0])
    _revise(bob, items[0], "b", failure_category="grasp_failure")
    version = dan.post(f"/api/items/{items[0]}/claim").json()["version"]
    r = dan.post(f"/api/items/{items[0]}/adjudication", json={"version": version, "idempotency_key": "j",
                 "rationale": hostile, "fields": {"failure_category": "grasp_failure"}})
    assert r.status_code == 200, r.text
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run_dir)}, "stage3": {"db_url": db_url}}))
    for args in (["history", str(items[0])], ["reviewers", "list"]):
        out = CliRunner().invoke(app, [*args, "-c", str(cfg)])
        assert out.exit_code == 0, out.output
        assert not any(ch in out.output for ch in "\x1b\x07\r\u202e"), (args, repr(out.output[:400]))
    assert "[bold]x[/bold]\\x1b[2J" in "".join(CliRunner().invoke(app, ["history", str(items[0]), "-c", str(cfg)])
                                               .output.split())
    assert "[red]mal\\x1b[8m" in CliRunner().invoke(app, ["reviewers", "list", "-c", str(cfg)]).output


@pytest.mark.parametrize("path,body,field", [
    ("/review", {"decision": "revise", "fields": {"fail_time_s": True}}, "fail_time_s"),
    ("/review", {"decision": "revise", "fields": {"fail_time_s": "2.5"}}, "fail_time_s"),
    ("/review", {"decision": "accept", "version": "0"}, "version"),
    ("/review", {"decision": "accept", "version": 0.0}, "version"),
    ("/review", {"decision": "flag", "reason": 5}, "reason"),
    ("/adjudication", {"exclude": 1, "rationale": "r"}, "exclude"),
])
def test_request_fields_are_never_coerced(server, people, items, engine, path, body, field):
    version = 0
    if path == "/adjudication":  # a conflict that dan has claimed, so only the body can be at fault
        accept(client(server, people, "ann"), items[0])
        _revise(client(server, people, "bob"), items[0], "b", failure_category="grasp_failure")
        version = client(server, people, "dan").post(f"/api/items/{items[0]}/claim").json()["version"]
    state = lambda: _dump(engine)  # noqa: E731
    before = state()
    body = {"version": version, "idempotency_key": "k", **body}
    r = client(server, people, "dan" if path == "/adjudication" else "ann").post(f"/api/items/{items[0]}{path}",
                                                                                json=body)
    assert r.status_code == 422 and r.json()["field"] == field, (r.status_code, r.text[:200])
    assert state() == before


def test_failed_sign_ins_are_logged_and_throttled_per_client(server, people, engine):
    url = f"{server.url}/api/login"
    for i in range(10):
        bad = httpx.post(url, json={"token": f"guess-{i}"}) if i % 2 else \
            httpx.get(f"{server.url}/api/me", headers={"Authorization": f"Bearer guess-{i}"})
        assert bad.status_code == 401, (i, bad.status_code)
    for attempt in ({"json": {"token": "guess-x"}}, {"json": {"token": people["ann"]}}):  # right or wrong: 429
        r = httpx.post(url, **attempt)
        assert r.status_code == 429 and int(r.headers["retry-after"]) >= 1
    r = httpx.get(f"{server.url}/api/me", headers={"Authorization": f"Bearer {people['ann']}"})
    assert r.status_code == 429
    with read_session(engine) as s:
        failed = s.scalars(select(Event).where(Event.kind == "login_failed")).all()
    assert len(failed) == 10 and all(e.actor == "@127.0.0.1" for e in failed)
    assert not any("guess" in json.dumps([e.detail, e.before, e.after]) for e in failed)  # never the token


def test_leases_are_capped_per_person_and_never_renewed_past_their_lifetime(run_dir, engine, people, items):
    from pipeline.review.api import create_app
    from pipeline.review.server import ThreadedServer
    from pipeline.review.workflow import QueueSettings

    cfg = QueueSettings(required_reviews=2, lease_seconds=600, max_leases=3, lease_max_s=10)
    with ThreadedServer(create_app(run_dir, engine, cfg)) as srv:
        ann = client(srv, people, "ann")
        for item_id in items[:3]:
            assert ann.post(f"/api/items/{item_id}/lease").status_code == 200
        r = ann.post(f"/api/items/{items[3]}/lease")
        assert r.status_code == 409 and "at most 3" in r.json()["detail"]
        with read_session(engine) as s:
            first = s.scalar(select(Lease).where(Lease.item_id == items[0]))
        assert first.expires_at - first.taken_at == pytest.approx(10, abs=0.01)  # not 600 s
        time.sleep(1)
        assert ann.post(f"/api/items/{items[0]}/lease").status_code == 200  # a renewal...
        with read_session(engine) as s:
            renewed = s.scalar(select(Lease).where(Lease.item_id == items[0]))
        assert renewed.expires_at == pytest.approx(first.expires_at, abs=0.01)  # ...that extends nothing


def test_slow_headers_and_slow_bodies_are_cut_off(run_dir, engine, settings, people, items):
    from pipeline.review.api import create_app
    from pipeline.review.limits import Limits
    from pipeline.review.server import ThreadedServer

    app = create_app(run_dir, engine, settings, limits=Limits(header_timeout_s=1, body_timeout_s=1))
    with ThreadedServer(app) as srv:
        def held(request: bytes) -> tuple[bytes, float]:
            with socket.create_connection(("127.0.0.1", srv.port), timeout=8) as sock:
                t = time.monotonic()
                sock.sendall(request)
                answer = b""
                while chunk := sock.recv(4096):  # until the server closes the connection
                    answer += chunk
                return answer, time.monotonic() - t

        auth = f"Authorization: Bearer {people['ann']}\r\n".encode()
        review = f"POST /api/items/{items[0]}/review HTTP/1.1\r\nHost: x\r\ncontent-type: application/json\r\n".encode()
        for request, status in (
                (b"GET /api/me HTTP/1.1\r\nHost: x\r\nx-slow: ", b"408"),  # headers never finished
                (review + auth + b"content-length: 100\r\n\r\n{\"decision\"", b"408"),  # signed in, body stalls
                (review + b"content-length: 1000\r\n\r\n{\"decision\"", b"401"),  # nobody: answered and closed
        ):
            answer, took = held(request)
            assert answer.split(b" ")[1] == status and took < 4, (request[:40], answer[:80], took)
    with read_session(engine) as s:
        assert s.get(Item, items[0]).n_reviews == 0


def _dump(engine) -> dict:
    """Every row of the queue's tables (failed sign-ins aside: logging them is intended)."""
    out = {}
    with read_session(engine) as s:
        for table in ("users", "items", "reviews", "leases", "adjudications", "events"):
            where = " WHERE kind <> 'login_failed'" if table == "events" else ""
            out[table] = [tuple(r) for r in s.execute(text(f"SELECT * FROM {table}{where} ORDER BY 1"))]
    return out


def test_fuzzed_write_bodies_never_give_a_500_nor_change_anything_when_refused(server, people, items, engine):
    import dataclasses

    from hypothesis import HealthCheck, given, settings, strategies as st

    from pipeline.review.throttle import FailureThrottle

    app = server.server.config.app  # one server for every example: a throttle that never trips
    app.state.review = dataclasses.replace(app.state.review, throttle=FailureThrottle(burst=10**9))
    ann, bob, dan = (client(server, people, n) for n in ("ann", "bob", "dan"))
    accept(ann, items[1])
    _revise(bob, items[1], "b", failure_category="grasp_failure")  # a conflict for dan to adjudicate
    names = ["decision", "fields", "reason", "version", "idempotency_key", "rationale", "exclude", "token",
             "fail_time_s", "recovery_level", "failure_category", "recovery_action"]
    scalars = (st.none() | st.booleans() | st.integers(min_value=-2**70, max_value=2**70)
               | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=30)
               | st.sampled_from(["accept", "revise", "flag", "L3", "grasp_failure", "k", people["ann"]]))
    values = st.recursive(scalars, lambda inner: st.lists(inner, max_size=4)
                          | st.dictionaries(st.sampled_from(names) | st.text(max_size=8), inner, max_size=5),
                          max_leaves=12)
    bodies = st.dictionaries(st.sampled_from(names), values, max_size=6) | values
    targets = st.sampled_from([(ann, f"/api/items/{items[0]}/review"), (dan, f"/api/items/{items[1]}/adjudication"),
                               (ann, f"/api/items/{items[2]}/lease"), (None, "/api/login")])
    raw = st.binary(max_size=64) | st.just(b"[" * 5000)

    @settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
    @given(target=targets, body=bodies, as_raw=st.booleans(), raw_bytes=raw)
    def check(target, body, as_raw, raw_bytes):
        who, path = target
        content = raw_bytes if as_raw else json.dumps(body, allow_nan=True).encode()
        before = _dump(engine)
        r = (who or httpx).post(f"{server.url}{path}" if who is None else path, content=content,
                                headers={"content-type": "application/json"})
        assert r.status_code < 500, (path, content[:200], r.status_code, r.text[:200])
        if r.status_code >= 400:
            assert _dump(engine) == before, (path, content[:200], r.status_code)

    check()
