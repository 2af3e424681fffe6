"""The review page in Debian's headless chromium (Playwright), against the real server."""

from __future__ import annotations

import os
import re
from pathlib import Path

import httpx
import pytest
from sqlalchemy import select

from pipeline.review.db import Item, Review, User, read_session, write_session

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


def sign_in(browser, server, token: str, size: tuple[int, int] = (1400, 1000)):
    # bypass_csp: Playwright evaluates its wait conditions with eval, which our CSP forbids
    page = browser.new_context(viewport={"width": size[0], "height": size[1]}, bypass_csp=True).new_page()
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


def step(page) -> int:
    return int(page.get_attribute(".player", "data-step"))


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
    s0 = step(page)  # pausing puts the playhead on the control step nearest to the frame shown
    assert frame(page) == s0 // 2  # 20 Hz control, 10 fps video
    page.keyboard.press("ArrowRight")
    page.wait_for_function(f"document.querySelector('.player').dataset.step === '{s0 + 1}'")
    page.keyboard.press("Shift+ArrowRight")
    page.wait_for_function(f"document.querySelector('.player').dataset.step === '{s0 + 11}'")
    page.click("#btn-step-1")
    page.wait_for_function(f"document.querySelector('.player').dataset.step === '{s0 + 10}'")
    assert frame(page) == (s0 + 10) // 2  # the nearest rendered frame (a tie goes to the earlier)
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
    for _ in range(16):
        page.keyboard.press("ArrowRight")
    page.wait_for_function("document.querySelector('.player').dataset.step === '16'")
    page.keyboard.press("t")  # failure time at the playhead: step 16 = 0.8 s
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
    adj, adj_errors = sign_in(browser, server, people["dan"], (1366, 768))
    adj.add_style_tag(content=STILL_CSS)
    adj.click(f"#adjudicate-{second}")
    adj.wait_for_selector("#compare")
    assert adj.locator(".field.edited").count() == 0  # nothing chosen yet: nothing edited
    shots = os.environ.get("REVIEW_SCREENSHOTS")  # a folder: keep pictures of the pages for people
    if shots:
        adj.wait_for_function("[...document.querySelectorAll('video')].every((v) => v.readyState >= 2)")
        adj.screenshot(path=f"{shots}/adjudication_1366x768.png")
    table = adj.text_content("#compare")
    assert "ann" in table and "bob" in table and "disputed" in table
    assert adj.locator("#compare tr.disputed").count() == 2  # time (0.8 vs 1.6 s) and level
    adj.keyboard.press("4")
    assert adj.locator(".field.edited").count() == 1
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
        adj.screenshot(path=f"{shots}/adjudication_decided_1366x768.png")
    adj.keyboard.press("s")
    adj.wait_for_selector("#adjudication-status.saved")
    with read_session(engine) as s:
        it = s.get(Item, second)
        assert it.status == "final" and it.resolution == "adjudicated"
        assert it.final["recovery_level"] == "L4" and it.final["fail_time_s"] == 1.3
    assert errors == [] and adj_errors == []


# --- the item page at laptop and desktop sizes ---------------------------------------------

REFERENCE = Path(__file__).parent / "item_page_1366x768.png"
# deterministic pictures: one font everywhere (canvas included), no transitions, no caret
STILL_CSS = """
* { font-family: "DejaVu Sans", sans-serif !important; transition: none !important; animation: none !important;
    caret-color: transparent !important; }
#toast { display: none !important; }
"""
SIZES = [(1366, 768), (1920, 1080), (1366, 657)]  # the last: a 1366x768 screen less the browser's bars
# every video has its seeked frame decoded (then one more animation frame for the paint)
VIDEOS_STILL = """() => [...document.querySelectorAll('video')].every((v) => !v.seeking && v.readyState >= 2)
    && new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(() => done(true))))"""


def open_page(browser, server, token: str, size: tuple[int, int], hash_: str):
    page, errors = sign_in(browser, server, token, size)
    page.add_style_tag(content=STILL_CSS)
    page.evaluate(f"location.hash = '{hash_}'")
    page.wait_for_selector("#decision-status, #adjudication-status, #compare")
    page.wait_for_function("[...document.querySelectorAll('video')].every((v) => v.readyState >= 2)")
    return page, errors


def out_of_view(page, selectors: list[str]) -> list[str]:
    """The selectors (each element they match) not wholly inside the viewport."""
    return page.evaluate("""(sels) => sels.flatMap((s) => [...document.querySelectorAll(s)].filter((el) => {
        const r = el.getBoundingClientRect();
        return r.width === 0 || r.top < 0 || r.left < 0 || r.bottom > innerHeight + 0.5 || r.right > innerWidth + 0.5;
    }).map(() => s))""", selectors)


def state(page) -> tuple[float, int, int]:
    d = page.evaluate("({...document.querySelector('.player').dataset})")
    return float(d["time"]), int(d["step"]), int(d["frame"])


def rgb(css: str) -> tuple[int, ...]:
    return tuple(int(x) for x in re.findall(r"\d+", css)[:3])


def compare_with_reference(png: bytes, reference: Path, videos: list[dict]) -> tuple[float, float]:
    """Shares of pixels off by more than 32 in some channel: outside the video boxes (at most
    0.1 %) and over the whole page (at most 1 %: the browser does not always scale a video
    frame with the same filter). Writes the reference when asked."""
    import io

    from PIL import Image, ImageChops, ImageDraw

    if os.environ.get("REVIEW_UPDATE_REFERENCE") or not reference.exists():
        reference.write_bytes(png)
    got, want = Image.open(io.BytesIO(png)).convert("RGB"), Image.open(reference).convert("RGB")
    assert got.size == want.size, f"{reference.name}: size {got.size}, reference {want.size}"
    r, g, b = ImageChops.difference(got, want).split()
    off = ImageChops.lighter(ImageChops.lighter(r, g), b).point(lambda v: 255 if v > 32 else 0)  # the largest channel
    whole = off.histogram()[255] / (got.size[0] * got.size[1])
    draw = ImageDraw.Draw(off)
    for b in videos:
        draw.rectangle([b["x"], b["y"], b["x"] + b["width"], b["y"] + b["height"]], fill=0)
    outside = off.histogram()[255] / (got.size[0] * got.size[1])
    assert outside <= 0.001 and whole <= 0.01, \
        f"the item page differs from {reference.name}: {outside:.2%} outside the videos, {whole:.2%} in all"
    return outside, whole


def test_item_page_fits_steps_on_the_control_grid_and_keeps_its_look(browser, server, engine, people, items):
    first, quarantined = items[0], items[-1]
    with write_session(engine) as s:  # the model's time between two video frames, three events at it
        it = s.get(Item, first)
        it.proposal = {**it.proposal, "fail_time_s": 1.55, "fail_step": 31}
        ev = it.context["events"][0]
        it.context = {**it.context, "events": [
            {**ev, "time_s": 1.55, "step": 31},
            {**ev, "time_s": 1.55, "step": 31, "kind": "object_dropped", "object": "plate_1", "detail": "fell 3 cm"},
            {**ev, "time_s": 1.55, "step": 31, "kind": "contact_started", "object": "cookie_box_1", "detail": ""},
            {**ev, "time_s": 2.5, "step": 50, "kind": "gripper_closed", "object": None, "detail": ""}]}
    shots = os.environ.get("REVIEW_SCREENSHOTS")
    page, errors = open_page(browser, server, people["ann"], SIZES[0], f"#/item/{first}")

    # the decision panel and every evidence track in view, nothing to scroll
    tracks = ["#btn-accept", "#btn-revise", "#btn-flag", "#marker-lane", "#event-lane", "#tracks", "#legend",
              "#ev-readout", "#video-main", "#video-wrist"]
    assert out_of_view(page, tracks) == []
    assert page.evaluate("document.scrollingElement.scrollHeight <= innerHeight")

    # both cameras side by side; V shows one at a time, then both again
    main, wrist = page.locator("#video-main").bounding_box(), page.locator("#video-wrist").bounding_box()
    assert abs(main["y"] - wrist["y"]) < 2 and wrist["x"] > main["x"] + main["width"] - 1
    for view in ("agentview", "robot0_eye_in_hand", "all"):
        page.keyboard.press("v")
        assert page.get_attribute("#videos", "data-view") == view
    # M: exactly the model's time (between frames 15 and 16 at 10 fps); T: exactly that, not an edit
    page.keyboard.press("m")
    assert state(page) == (1.55, 31, 15)
    page.keyboard.press("t")
    assert page.input_value("#input-fail-time") == "1.55"
    assert page.locator(".field.edited").count() == 0
    page.keyboard.press("s")
    assert "Nothing is edited" in page.text_content("#decision-status")
    # arrows walk the 0.05 s grid; the video shows the nearest rendered frame
    page.keyboard.press("ArrowRight")
    assert state(page) == (1.6, 32, 16)
    page.keyboard.press("ArrowRight")
    page.keyboard.press("t")
    assert state(page)[:2] == (1.65, 33) and page.input_value("#input-fail-time") == "1.65"
    assert page.locator("#field-fail_time_s.edited").count() == 1
    page.keyboard.press("Shift+ArrowLeft")
    assert state(page)[:2] == (1.15, 23)
    page.fill("#input-fail-time", "1.234")  # a typed time shows the control step it is stored as
    page.keyboard.press("Escape")
    assert page.input_value("#input-fail-time") == "1.25"
    page.keyboard.press("m")

    # events: labelled, stacked where they share a time, the whole list in a tooltip
    stacks = page.locator(".ev-stack")
    assert stacks.count() == 2 and stacks.first.get_attribute("data-n") == "3"
    assert stacks.first.locator(".ev-label").all_text_contents() == [
        "toppled · black bowl", "dropped · plate", "contact started · cookie box"]
    stacks.first.hover()
    tip = page.text_content("#ev-tip")
    assert "object toppled" in tip and "plate_1" in tip and "cookie_box_1" in tip
    page.mouse.move(0, 0)
    # colours: object lines chromatic, time markers achromatic, so never confused
    def colours(selector: str, prop: str) -> list[tuple[int, ...]]:
        return [rgb(c) for c in page.eval_on_selector_all(selector, f"(els) => els.map((e) => getComputedStyle(e).{prop})")]

    objects, markers = colours(".obj-key i", "backgroundColor"), colours(".mtag", "color")
    event = colours(".ev-stack", "borderLeftColor")[0]
    assert len(objects) == 3 and all(max(c) - min(c) > 80 for c in objects) and event not in objects
    assert len(markers) == 2 and all(max(c) - min(c) < 40 for c in markers)

    # the look: compared with the stored reference (paused at the model's time, fixed size and font)
    page.keyboard.press("t")
    page.wait_for_function(VIDEOS_STILL)
    png = page.screenshot(animations="disabled", caret="hide")
    compare_with_reference(png, REFERENCE, [page.locator(v).bounding_box() for v in ("#video-main", "#video-wrist")])
    if shots:
        Path(shots, "item_1366x768.png").write_bytes(png)
    assert "0 done today" in page.text_content("#progress")
    page.keyboard.press("a")
    page.wait_for_selector("#decision-status.saved")
    assert stored(engine, first, "ann").values["fail_time_s"] == 1.55
    wait_next_item(page, first)
    page.wait_for_function("document.querySelector('#progress').textContent.includes('1 done today')")

    # a quarantined item: A is disabled, so S never suggests it, even after a refused submission
    page.evaluate(f"location.hash = '#/item/{quarantined}'")
    page.wait_for_selector("#quarantine-banner")
    assert page.is_disabled("#btn-accept")
    if shots:
        page.wait_for_function(VIDEOS_STILL)
        page.screenshot(path=f"{shots}/item_quarantined_1366x768.png")
    page.keyboard.press("s")
    status = page.text_content("#decision-status")
    assert "press A" not in status and "set every field" in status
    page.keyboard.press("2")
    page.keyboard.press("s")
    page.wait_for_selector("#decision-status.error")
    assert page.is_disabled("#btn-accept")

    # the queue shows the reviewer's progress; agreement once an item has closed
    r = httpx.post(f"{server.url}/api/items/{first}/review", headers={"Authorization": f"Bearer {people['bob']}"},
                   json={"decision": "accept", "version": 0, "idempotency_key": "bob-1"})
    assert r.status_code == 200
    page.keyboard.press("q")
    page.wait_for_selector("#my-progress")
    assert page.text_content("#progress-today").startswith("1")
    assert page.text_content("#progress-agreement") == "100 %agreement (1 closed)"
    assert "agreement 100 % over 1 closed item" in page.text_content("#progress")
    if shots:
        page.screenshot(path=f"{shots}/queue_1366x768.png")

    # a desktop screen, and a 1366x768 laptop screen less the browser's bars: the same in view
    for size in SIZES[1:]:
        other, other_errors = open_page(browser, server, people["bob"], size, f"#/item/{items[1]}")
        assert out_of_view(other, tracks) == [] and other.evaluate("document.scrollingElement.scrollHeight <= innerHeight")
        if shots:
            other.screenshot(path=f"{shots}/item_{size[0]}x{size[1]}.png")
        assert other_errors == []
        other.context.close()
    assert errors == []


def test_adjudication_page_fits_without_scrolling(browser, server, engine, people, items):
    # the hardest case: every field disputed (ann revises all four, bob accepts the model)
    item = items[0]
    for name, body in (("ann", {"decision": "revise", "fields": {
            "fail_time_s": 0.8, "recovery_level": "L1", "failure_category": "grasp_failure",
            "recovery_action": "Open the gripper, then grasp the bowl again from above"}}),
            ("bob", {"decision": "accept"})):
        r = httpx.post(f"{server.url}/api/items/{item}/review", headers={"Authorization": f"Bearer {people[name]}"},
                       json={**body, "version": 0, "idempotency_key": f"{name}-fit"})
        assert r.status_code == 200, r.text
    with read_session(engine) as s:
        assert len(s.get(Item, item).disputed) == 4
    shots = os.environ.get("REVIEW_SCREENSHOTS")
    panel = ["#compare", "#btn-adjudicate", "#rationale", "#exclude", "#adjudication-status", "#history summary",
             "#marker-lane", "#event-lane", "#tracks", "#legend", "#ev-readout", "#video-main", "#video-wrist"]
    for size in SIZES[:2]:
        page, errors = open_page(browser, server, people["dan"], size, f"#/adjudicate/{item}")
        page.wait_for_selector("#btn-adjudicate")
        if shots:
            page.wait_for_function(VIDEOS_STILL)
            page.screenshot(path=f"{shots}/adjudication_all_disputed_{size[0]}x{size[1]}.png")
        assert out_of_view(page, panel) == [], size
        assert page.evaluate("document.scrollingElement.scrollHeight <= innerHeight"), size
        side = page.evaluate("(() => { const s = document.querySelector('.side'); "
                             "return [s.scrollHeight, s.clientHeight]; })()")
        assert side[0] <= side[1], f"the right column scrolls at {size}: {side}"
        assert errors == []
        page.context.close()
