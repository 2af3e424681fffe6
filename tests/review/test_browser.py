"""The review page in Debian's headless chromium (Playwright), against the real server."""

from __future__ import annotations

import os
import re

import httpx
import pytest
from sqlalchemy import select

from pipeline.review.db import Item, Review, User, read_session

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]

pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="needs Debian's chromium (apt-get install chromium)"),
]


@pytest.fixture(scope="module")
def browser():
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield b
        b.close()


def sign_in(browser, server, token: str):
    # bypass_csp: Playwright evaluates its wait conditions with eval, which our CSP forbids
    page = browser.new_context(viewport={"width": 1400, "height": 1000}, bypass_csp=True).new_page()
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(server.url + "/")
    page.fill("#token", token)
    page.press("#token", "Enter")
    page.wait_for_selector("#btn-start")
    return page, errors


def item_id(page) -> int:
    page.wait_for_function("location.hash.startsWith('#/item/')")
    page.wait_for_selector("#decision-status")
    return int(re.search(r"#/item/(\d+)", page.url).group(1))


def frame(page) -> int:
    return int(page.get_attribute(".player", "data-frame"))


def wait_next_item(page, after: int) -> int:
    page.wait_for_function(f"location.hash.startsWith('#/item/') && location.hash !== '#/item/{after}'")
    return item_id(page)


def stored(engine, item: int, name: str) -> Review | None:
    with read_session(engine) as s:
        return s.scalar(select(Review).join(User, User.id == Review.reviewer_id)
                        .where(Review.item_id == item, User.name == name))


def test_review_and_adjudicate_in_the_browser(browser, server, engine, people, items):
    page, errors = sign_in(browser, server, people["ann"])
    assert "ann" in page.text_content("#whoami")

    # --- item 1: play, step frames, accept -------------------------------------------------
    page.keyboard.press("n")
    first = item_id(page)
    assert page.text_content("#instruction").strip("“”") == "pick up the black bowl and place it on the plate"
    assert "simstate" in page.text_content("#model-version")  # the suggestion names its model
    page.wait_for_function("document.querySelector('#video-main').readyState >= 2")
    page.keyboard.press("Space")
    page.wait_for_function("document.querySelector('#video-main').currentTime > 0.3")
    page.keyboard.press("Space")
    page.wait_for_function("document.querySelector('#video-main').paused")
    f0 = frame(page)
    page.keyboard.press("ArrowRight")
    page.wait_for_function(f"document.querySelector('.player').dataset.frame === '{f0 + 1}'")
    page.keyboard.press("Shift+ArrowRight")
    page.wait_for_function(f"document.querySelector('.player').dataset.frame === '{f0 + 11}'")
    page.click("#btn-step-1")
    page.wait_for_function(f"document.querySelector('.player').dataset.frame === '{f0 + 10}'")
    assert page.evaluate("document.querySelector('#video-wrist').paused")  # the wrist view follows
    page.keyboard.press("]")
    assert page.evaluate("document.querySelector('#video-main').playbackRate") == 1.5
    page.keyboard.press("m")  # jump to the model's failure time
    page.wait_for_function("document.querySelector('#readout').textContent.includes('1.50 s')")
    page.keyboard.press("a")
    page.wait_for_selector("#decision-status.saved")
    second = wait_next_item(page, first)
    assert stored(engine, first, "ann").decision == "accept"

    # --- item 2: revise with an invalid, then a valid value ---------------------------------
    page.fill("#input-fail-time", "999")
    page.keyboard.press("Escape")
    page.keyboard.press("3")
    page.keyboard.press("1")  # level L1
    page.keyboard.press("s")
    page.wait_for_selector("#field-fail_time_s.invalid")
    assert "fail_time_s" in page.text_content("#err-fail_time_s")
    assert "Not saved" in page.text_content("#decision-status")
    assert stored(engine, second, "ann") is None
    page.keyboard.press("Home")
    for _ in range(8):
        page.keyboard.press("ArrowRight")
    page.wait_for_function("document.querySelector('.player').dataset.frame === '8'")
    page.keyboard.press("t")  # failure time at the playhead: frame 8 = 0.8 s
    assert page.input_value("#input-fail-time") == "0.8"
    page.keyboard.press("s")
    page.wait_for_selector("#decision-status.saved")
    third = wait_next_item(page, second)
    review = stored(engine, second, "ann")
    assert review.decision == "revise" and review.values["fail_time_s"] == 0.8
    assert review.values["recovery_level"] == "L1" and sorted(review.edited) == ["fail_time_s", "recovery_level"]

    # --- item 3: flag as ambiguous with a reason --------------------------------------------
    page.keyboard.press("f")
    page.fill("#flag-reason", "two things go wrong at once")
    page.press("#flag-reason", "Enter")
    page.wait_for_selector("#decision-status.saved")
    wait_next_item(page, third)
    flagged = stored(engine, third, "ann")
    assert flagged.decision == "flag" and flagged.flag_reason == "two things go wrong at once"

    # --- bob (over the API) accepts item 2: ann's L1 vs the model's L3 -> conflict ----------
    r = httpx.post(f"{server.url}/api/items/{second}/review", headers={"Authorization": f"Bearer {people['bob']}"},
                   json={"decision": "accept", "version": 0, "idempotency_key": "bob-2"})
    assert r.status_code == 200
    with read_session(engine) as s:
        assert s.get(Item, second).status == "conflict"

    # --- dan, an adjudicator, decides the disputed fields in his own session -----------------
    adj, adj_errors = sign_in(browser, server, people["dan"])
    adj.click(f"#adjudicate-{second}")
    adj.wait_for_selector("#compare")
    table = adj.text_content("#compare")
    assert "ann" in table and "bob" in table and "disputed" in table
    assert adj.locator("#compare tr.disputed").count() == 2  # time (0.8 vs 1.6 s) and level
    shots = os.environ.get("REVIEW_SCREENSHOTS")  # a folder: keep pictures of the pages for people
    adj.keyboard.press("4")
    adj.fill("#input-fail-time", "1.3")
    adj.keyboard.press("Escape")
    adj.keyboard.press("s")  # no rationale yet: refused, naming it
    adj.wait_for_selector("#adjudication-status.error")
    assert "rationale" in adj.text_content("#adjudication-status")
    adj.fill("#rationale", "the box ends up blocking the plate")
    adj.keyboard.press("Escape")
    adj.click("#history summary")  # the item's audit history, oldest first
    adj.wait_for_selector("#history ol.events li")
    assert "enqueued" in adj.text_content("#history") and "claimed" in adj.text_content("#history")
    if shots:
        adj.screenshot(path=f"{shots}/adjudication.png", full_page=True)
    adj.keyboard.press("s")
    adj.wait_for_selector("#adjudication-status.saved")
    with read_session(engine) as s:
        it = s.get(Item, second)
        assert it.status == "final" and it.resolution == "adjudicated"
        assert it.final["recovery_level"] == "L4" and it.final["fail_time_s"] == 1.3
    assert errors == [] and adj_errors == []
