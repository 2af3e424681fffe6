"""Model-vs-final statistics, grouped by model and prompt version, and their PNG."""

from __future__ import annotations

from sqlalchemy import select

from pipeline.review import report, workflow
from pipeline.review.db import Item, User, read_session, write_session


def test_model_quality_is_grouped_by_version_and_counts_confusions(engine, people, items, settings, tmp_path):
    with write_session(engine) as s:  # two characterizer versions over the localized items
        for n, it in enumerate(s.scalars(select(Item).where(Item.quarantined.is_(False)).order_by(Item.id))):
            if n % 2:
                it.proposal = {**it.proposal, "characterizer": {"source": "openai", "model": "qwen",
                                                                "prompt_name": "characterize.v1.zh", "prompt_hash": "abcdef123"}}
    with read_session(engine) as s:
        users = {u.name: u for u in s.scalars(select(User))}
        open_ids = [i.id for i in s.scalars(select(Item).where(Item.quarantined.is_(False)).order_by(Item.id))]
    for n, item_id in enumerate(open_ids):
        for name in ("ann", "bob"):
            fields = {"recovery_level": "L2"} if n == 0 else {}  # both reviewers revise item 0 to L2
            body = {"decision": "revise" if fields else "accept", "fields": fields, "idempotency_key": name}
            with write_session(engine) as s:
                workflow.submit_review(s, users[name], item_id, body, settings)
    with read_session(engine) as s:
        out = report.summary(s, settings.time_tolerance_s)
    groups = {g["version"]: g for g in out["model_vs_final"]["by_characterizer"]}
    assert set(groups) == {"simstate", "qwen / characterize.v1.zh@abcdef12"}
    sim = groups["simstate"]
    assert sim["n"] == 3 and sim["level"]["matrix"][1][2] == 1 and sim["level"]["matrix"][2][2] == 2
    assert sim["level"]["accuracy"] == round(2 / 3, 4) and sim["category"]["accuracy"] == 1.0
    assert out["model_vs_final"]["by_localizer"][0]["errors_s"] == [0.0] * 5
    assert out["agreement"]["items"] == 5 and out["agreement"]["recovery_level"]["percent_agreement"] == 1.0
    png = report.plot(out, tmp_path / "confusion.png")
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000
