"""Issue 29's probe findings 1, 3 and 5 as real requests against a real server (uvicorn on
loopback, SQLite and PostgreSQL): the generator's truth and the logged steps are never
served; oversized requests are refused before anyone is authenticated or anything parsed;
hostile JSON and out-of-range ids are 4xx, never 500."""

from __future__ import annotations

import socket
from pathlib import Path

import httpx
import pytest

from tests.review.test_api import client

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
