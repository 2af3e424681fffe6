"""A reviewer's working day over HTTP: control-grid times, no-op revisions, sign-in mistakes, progress."""

from __future__ import annotations

import httpx
import pytest
from sqlalchemy import func, select

from pipeline.review.db import Event, Review, read_session


def client(server, people, name: str) -> httpx.Client:
    return httpx.Client(base_url=server.url, headers={"Authorization": f"Bearer {people[name]}"}, timeout=10)


def revise(c: httpx.Client, item_id: int, key: str, version: int = 0, **fields) -> httpx.Response:
    return c.post(f"/api/items/{item_id}/review", json={"decision": "revise", "version": version,
                                                        "idempotency_key": key, "fields": fields})


def test_the_item_payload_gives_the_control_step_the_steps_and_both_cameras(server, people, items):
    media = client(server, people, "ann").get(f"/api/items/{items[0]}").json()["media"]
    assert media["control_step_s"] == 0.05 and media["n_steps"] == 61  # 3.0 s at 20 Hz, both ends
    assert [c["name"] for c in media["cameras"]] == ["agentview", "robot0_eye_in_hand"]
    assert all(c["url"].endswith(f"video_{c['name']}.mp4") for c in media["cameras"])


def test_setting_the_models_own_time_is_stored_as_an_accept_not_an_edit(server, people, items, engine):
    ann = client(server, people, "ann")
    model_t = ann.get(f"/api/items/{items[0]}").json()["proposal"]["fail_time_s"]  # 1.5
    r = revise(ann, items[0], "t", fail_time_s=model_t + 1e-9)
    assert r.status_code == 200 and r.json()["decision"] == "accept"
    mine = ann.get(f"/api/items/{items[0]}").json()["my_review"]
    assert mine["edited"] == [] and mine["values"]["fail_time_s"] == model_t


def test_an_off_grid_time_is_stored_on_the_control_grid(server, people, items):
    ann = client(server, people, "ann")
    r = revise(ann, items[0], "t", fail_time_s=2.26)
    assert r.status_code == 200 and r.json()["values"]["fail_time_s"] == 2.25 and r.json()["values"]["fail_step"] == 45
    assert r.json()["decision"] == "revise"


def test_a_revision_that_changes_nothing_is_not_stored(server, people, items, engine):
    ann = client(server, people, "ann")
    first = revise(ann, items[0], "a", fail_time_s=2.5)
    assert first.status_code == 200 and first.json()["version"] == 1
    again = revise(ann, items[0], "b", version=1, fail_time_s=2.51)  # the same control step (a text "2.5" is a 422)
    assert again.status_code == 200 and again.json()["replayed"] is True and again.json()["version"] == 1
    with read_session(engine) as s:
        assert s.scalar(select(Review.version).where(Review.item_id == items[0])) == 1
        kinds = s.scalars(select(Event.kind).where(Event.item_id == items[0])).all()
    assert "review_changed" not in kinds


def test_sending_the_accepted_models_time_again_as_a_revision_changes_nothing(server, people, items, engine):
    ann = client(server, people, "ann")
    model_t = ann.get(f"/api/items/{items[0]}").json()["proposal"]["fail_time_s"]
    assert ann.post(f"/api/items/{items[0]}/review", json={"decision": "accept", "version": 0,
                                                           "idempotency_key": "a"}).json()["version"] == 1
    again = revise(ann, items[0], "b", version=1, fail_time_s=model_t + 0.01)  # 1.51 when it is 1.5: the same step
    assert again.status_code == 200 and again.json()["replayed"] is True and again.json()["decision"] == "accept"
    with read_session(engine) as s:
        review = s.scalar(select(Review).where(Review.item_id == items[0]))
        kinds = s.scalars(select(Event.kind).where(Event.item_id == items[0])).all()
    assert (review.version, review.decision, review.edited) == (1, "accept", []) and "review_changed" not in kinds


def test_the_agreed_time_of_two_reviewers_lies_on_the_control_grid(server, people, items, engine):
    ann, bob = client(server, people, "ann"), client(server, people, "bob")
    assert revise(ann, items[0], "a", fail_time_s=1.95).status_code == 200
    assert revise(bob, items[0], "b", fail_time_s=2.2).status_code == 200  # mean 2.075 s: off the grid
    adj = client(server, people, "dan").get(f"/api/items/{items[0]}/adjudication").json()
    assert adj["status"] == "final" and adj["final"]["fail_time_s"] == 2.05 and adj["final"]["fail_step"] == 41


@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded", None])
def test_a_sign_in_with_the_wrong_content_type_is_refused_without_echoing_the_token(server, people, content_type):
    token = people["ann"]
    headers = {"content-type": content_type} if content_type else {}
    for body in (f'{{"token": "{token}"}}', f"token={token}"):
        r = httpx.post(f"{server.url}/api/login", content=body, headers=headers)
        assert r.status_code == 415 and token not in r.text and "set-cookie" not in r.headers


@pytest.mark.parametrize("body", ['{"token": 12345678901234567890123}', '{"tokn": "SECRET"}', '["SECRET"]',
                                  '{"token": "SECRET", ', '"SECRET"'])
def test_no_sign_in_error_echoes_what_was_sent(server, body):
    secret = "s3cr3t-" + "x" * 30
    r = httpx.post(f"{server.url}/api/login", content=body.replace("SECRET", secret),
                   headers={"content-type": "application/json"})
    assert 400 <= r.status_code < 500 and secret not in r.text and "12345678901234567890123" not in r.text


def test_a_validation_error_never_echoes_a_long_value_or_a_whole_body(server, people, items):
    ann = client(server, people, "ann")
    secret = "s3cr3t-" + "y" * 50
    r = ann.post(f"/api/items/{items[0]}/review", content=f'"{secret}"', headers={"content-type": "application/json"})
    assert r.status_code == 422 and secret not in r.text
    r = ann.post(f"/api/items/{items[0]}/review", json={"decision": secret, "version": 0, "idempotency_key": "k"})
    assert r.status_code == 422 and r.json()["field"] == "decision" and secret not in r.text
    r = ann.post(f"/api/items/{items[0]}/review", json={"decision": "nope", "version": 0, "idempotency_key": "k"})
    assert "'nope'" in r.json()["detail"]  # short, non-secret values are still shown to help


def test_progress_counts_today_what_is_left_and_agreement_once_items_close(server, people, items, engine):
    ann, bob = client(server, people, "ann"), client(server, people, "bob")
    start = ann.get("/api/progress").json()
    assert start["done_today"] == 0 and start["left"] == len(items)
    assert start["agreement"] == {"closed_items": 0, "pairs": 0, "all_fields": None,
                                  "by_field": dict.fromkeys(start["agreement"]["by_field"])}
    # item 0: both accept (agree); item 1: bob changes the category (disagree on one field)
    for i, item in enumerate(items[:2]):
        assert revise(ann, item, f"a{i}", fail_time_s=1.5 + 0.1 * i + 0.05).status_code == 200
    assert revise(bob, items[0], "b0", fail_time_s=1.5).status_code == 200
    mid = ann.get("/api/progress").json()
    assert mid["done_today"] == 2 and mid["left"] == len(items) - 2
    assert mid["agreement"]["closed_items"] == 1 and mid["agreement"]["all_fields"] == 1.0
    assert revise(bob, items[1], "b1", failure_category="grasp_failure").status_code == 200
    done = ann.get("/api/queue").json()["progress"]
    assert done["agreement"]["closed_items"] == 2 and done["agreement"]["pairs"] == 2
    assert done["agreement"]["all_fields"] == 0.5 and done["agreement"]["by_field"]["failure_category"] == 0.5
    assert done["agreement"]["by_field"]["fail_time_s"] == 1.0
    # bob's own numbers are his own
    assert bob.get("/api/progress").json()["done_today"] == 2
    with read_session(engine) as s:
        assert s.scalar(select(func.count(Review.id))) == 4
