"""The HTTP API on a real uvicorn server on loopback, with a real SQLite queue."""

from __future__ import annotations

import httpx
import pytest


def client(server, people, name: str) -> httpx.Client:
    return httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {people[name]}"}, timeout=10)


def browser_like(server, people, name: str) -> tuple[httpx.Client, str]:
    """Signed in with the session cookie, as the web page is; returns (client, csrf token)."""
    c = httpx.Client(base_url=server.url, timeout=10)
    r = c.post("/api/login", json={"token": people[name]})
    assert r.status_code == 200, r.text
    return c, r.json()["csrf"]


def accept(c: httpx.Client, item_id: int, key: str = "k", **extra) -> httpx.Response:
    return c.post(f"/api/items/{item_id}/review", json={"decision": "accept", "version": 0, "idempotency_key": key,
                                                         **extra})


def test_requests_without_sign_in_get_401(server, items):
    r = httpx.get(f"{server.url}/api/items/{items[0]}")
    assert r.status_code == 401


def test_a_cookie_write_without_the_csrf_header_gets_403(server, people, items):
    c, csrf = browser_like(server, people, "ann")
    assert c.get(f"/api/items/{items[0]}").status_code == 200
    r = accept(c, items[0])
    assert r.status_code == 403 and "CSRF" in r.json()["detail"]
    r = c.post(f"/api/items/{items[0]}/review", headers={"X-CSRF-Token": csrf},
               json={"decision": "accept", "version": 0, "idempotency_key": "k"})
    assert r.status_code == 200 and r.json()["replayed"] is False


def test_a_reviewer_token_gets_403_on_adjudication(server, people, items):
    ann = client(server, people, "ann")
    assert ann.get(f"/api/items/{items[0]}/adjudication").status_code == 403
    r = ann.post(f"/api/items/{items[0]}/adjudication",
                 json={"fields": {}, "rationale": "r", "version": 1, "idempotency_key": "k"})
    assert r.status_code == 403 and "adjudicator" in r.json()["detail"]
    assert ann.post(f"/api/items/{items[0]}/claim").status_code == 403


@pytest.mark.parametrize("path", [
    "/media/../../../../etc/passwd",
    "/media/..%2F..%2F..%2F..%2Fetc%2Fpasswd",
    "/media/%2Fetc%2Fpasswd",
    "/media/stage3/review.sqlite",
    "/media/stage3/annotations/libero_spatial/t/episode_e.json",  # other reviewers' values
    "/media/stage2/../../outside.mp4",
])
def test_a_path_traversal_media_request_gets_404(server, people, items, run_dir, path):
    (run_dir.parent / "outside.mp4").write_bytes(b"secret")
    labels = run_dir / "stage3" / "annotations" / "libero_spatial" / "t" / "episode_e.json"
    labels.parent.mkdir(parents=True, exist_ok=True)
    labels.write_text('{"reviews": "secret"}')
    r = client(server, people, "ann").get(path)
    assert r.status_code == 404
    assert b"secret" not in r.content and b"root:" not in r.content


def test_media_inside_the_run_is_served_with_range_support(server, people, items):
    ann = client(server, people, "ann")
    url = ann.get(f"/api/items/{items[0]}").json()["media"]["videos"]["agentview"]
    full = ann.get(url)
    assert full.status_code == 200 and full.content[4:8] == b"ftyp"
    part = ann.get(url, headers={"Range": "bytes=0-99"})
    assert part.status_code == 206 and len(part.content) == 100


def test_a_bad_field_gets_a_422_that_names_it(server, people, items):
    ann = client(server, people, "ann")
    r = ann.post(f"/api/items/{items[0]}/review", json={"decision": "revise", "version": 0, "idempotency_key": "a",
                                                        "fields": {"recovery_level": "L7"}})
    assert r.status_code == 422 and r.json()["field"] == "recovery_level" and "L7" in r.json()["detail"]
    r = ann.post(f"/api/items/{items[0]}/review", json={"decision": "revise", "version": 0, "idempotency_key": "b",
                                                        "fields": {"fail_time_s": 1e6}})
    assert r.status_code == 422 and r.json()["field"] == "fail_time_s"
    r = ann.post(f"/api/items/{items[0]}/review", json={"decision": "flag", "version": 0, "idempotency_key": "c"})
    assert r.status_code == 422 and r.json()["field"] == "reason"


def test_a_stale_write_gets_409_and_a_repeat_is_harmless(server, people, items):
    ann = client(server, people, "ann")
    first = accept(ann, items[0], key="tab-1")
    assert first.status_code == 200 and first.json()["version"] == 1
    again = accept(ann, items[0], key="tab-1")
    assert again.status_code == 200 and again.json()["replayed"] is True
    stale = ann.post(f"/api/items/{items[0]}/review", json={"decision": "flag", "reason": "odd", "version": 0,
                                                            "idempotency_key": "tab-2"})
    assert stale.status_code == 409 and stale.json()["current"] == {"version": 1}


def test_a_reviewer_never_sees_other_reviewers_decisions(server, people, items):
    ann, bob = client(server, people, "ann"), client(server, people, "bob")
    assert bob.post(f"/api/items/{items[0]}/review", json={"decision": "revise", "version": 0, "idempotency_key": "b",
                                                          "fields": {"recovery_level": "L1"}}).status_code == 200
    view = ann.get(f"/api/items/{items[0]}").json()
    text = str(view)
    assert view["my_review"] is None and "bob" not in text and "L1" not in text.replace("'L1', ", "")
    assert "n_reviews" not in view and view["state"] == "open"
    assert view["proposal"]["recovery_level"] == "L3"  # the model's suggestion is shown


def test_conflict_is_adjudicated_over_http_by_someone_who_did_not_review_it(server, people, items):
    ann, bob, dan = (client(server, people, n) for n in ("ann", "bob", "dan"))
    accept(ann, items[1])
    bob.post(f"/api/items/{items[1]}/review", json={"decision": "revise", "version": 0, "idempotency_key": "b",
                                                   "fields": {"failure_category": "grasp_failure"}})
    queue = dan.get("/api/queue").json()
    assert [c["id"] for c in queue["conflicts"]] == [items[1]]
    view = dan.get(f"/api/items/{items[1]}/adjudication").json()
    assert view["disputed"] == ["failure_category"]
    assert {r["reviewer"]: r["values"]["failure_category"] for r in view["reviews"]} == {
        "ann": "object_displacement", "bob": "grasp_failure"}
    claimed = dan.post(f"/api/items/{items[1]}/claim").json()
    body = {"fields": {"failure_category": "grasp_failure"}, "rationale": "the grasp slipped first",
            "version": view["version"], "idempotency_key": "adj"}
    assert dan.post(f"/api/items/{items[1]}/adjudication", json=body).status_code == 409  # claim bumped the version
    r = dan.post(f"/api/items/{items[1]}/adjudication", json={**body, "version": claimed["version"]})
    assert r.status_code == 200 and r.json()["final"]["failure_category"] == "grasp_failure"
    assert dan.post(f"/api/items/{items[1]}/adjudication", json={**body, "version": claimed["version"]}).json()[
        "replayed"] is True
    history = client(server, people, "eve").get(f"/api/items/{items[1]}/history").json()["events"]
    kinds = [e["kind"] for e in history]
    assert kinds[0] == "enqueued" and "adjudicated" in kinds and kinds.count("review") == 2


def test_queue_next_leases_items_in_turn_and_reports_none_when_empty(server, people, items):
    ann = client(server, people, "ann")
    seen = []
    for _ in range(len(items) + 1):
        nxt = ann.post("/api/queue/next").json()["item"]
        if nxt is None:
            break
        seen.append(nxt)
        body = {"decision": "flag", "reason": "test", "version": 0, "idempotency_key": f"q{nxt}"}
        assert ann.post(f"/api/items/{nxt}/review", json=body).status_code == 200
    assert sorted(seen) == sorted(items)


def test_evidence_and_frames_come_as_columns(server, people, items):
    ann = client(server, people, "ann")
    ev = ann.get(f"/api/items/{items[0]}/evidence").json()
    fr = ann.get(f"/api/items/{items[0]}/frames").json()
    assert len(ev["time_s"]) == len(ev["gripper_opening"]) == 61
    assert set(ev["displacement"]) == {"akita_black_bowl_1", "plate_1", "cookie_box_1"}
    assert fr["time_s"][:3] == [0.0, 0.1, 0.2]


def test_the_page_is_served_with_a_strict_content_security_policy(server):
    r = httpx.get(f"{server.url}/")
    assert r.status_code == 200 and "js/main.js" in r.text
    csp = r.headers["content-security-policy"]
    assert "default-src 'self'" in csp and "frame-ancestors 'none'" in csp and "unsafe-eval" not in csp
    assert r.headers["x-content-type-options"] == "nosniff"


def test_a_malformed_decision_is_a_422_that_is_not_sniffed(server, people, items):
    """(was checked on the fast lane's answers; the lane is gone, the headers stay on every answer)"""
    ann = client(server, people, "ann")
    r = ann.post(f"/api/items/{items[0]}/review", content=b"{not json", headers={"Content-Type": "application/json"})
    assert r.status_code == 422 and "detail" in r.json()
    assert r.headers["x-content-type-options"] == "nosniff"


def test_without_a_lease_a_reviewer_cannot_take_a_place_others_hold(server, people, items):
    for name in ("ann", "bob"):
        assert client(server, people, name).post(f"/api/items/{items[0]}/lease").status_code == 200
    cat = client(server, people, "cat")
    assert cat.post(f"/api/items/{items[0]}/lease").status_code == 409
    r = accept(cat, items[0])
    assert r.status_code == 409 and "held by other reviewers" in r.json()["detail"]
    assert accept(client(server, people, "ann"), items[0]).status_code == 200
