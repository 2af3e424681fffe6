"""The state machine against a real SQLite database (no server)."""

from __future__ import annotations

import pytest
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError

from pipeline.review import adjudication, workflow
from pipeline.review.db import Item, Lease, Review, User, read_session, write_session
from pipeline.review.enqueue import enqueue
from pipeline.review.errors import Forbidden, Invalid, Stale
from tests.review.conftest import ACTION


def user(engine, name: str) -> User:
    with read_session(engine) as s:
        return s.scalar(select(User).where(User.name == name))


def item(engine, item_id: int) -> Item:
    with read_session(engine) as s:
        return s.get(Item, item_id)


def _digest(body: dict) -> str:
    import hashlib

    return hashlib.sha256(repr(body).encode()).hexdigest()[:16]  # idempotency keys hold 100 characters


def decide(engine, who: str, item_id: int, settings, key: str | None = None, version: int = 0, **body):
    body.setdefault("decision", "accept")
    with write_session(engine) as s:
        r, replayed = workflow.submit_review(s, user(engine, who), item_id,
                                             {"idempotency_key": key or f"{who}-{item_id}-{_digest(body)}", "version": version,
                                              **body}, settings)
        return r.version, replayed


def test_two_accepts_make_the_item_final_with_the_model_values(engine, people, items, settings):
    first = items[0]
    decide(engine, "ann", first, settings)
    assert item(engine, first).status == "reviewed"
    decide(engine, "bob", first, settings)
    it = item(engine, first)
    assert it.status == "final" and it.resolution == "agreed"
    assert it.final["recovery_level"] == "L3" and it.final["recovery_action"] == ACTION
    assert it.final["fail_time_s"] == it.proposal["fail_time_s"]


def test_a_third_reviewer_is_refused_once_k_reviews_exist(engine, people, items, settings):
    decide(engine, "ann", items[0], settings)
    decide(engine, "bob", items[0], settings)
    with pytest.raises(Stale, match="no longer takes reviews"):
        decide(engine, "cat", items[0], settings)
    with read_session(engine) as s:
        assert s.scalar(select(Item.n_reviews).where(Item.id == items[0])) == 2


def test_database_rejects_a_second_review_by_the_same_reviewer(engine, people, items):
    ann = user(engine, "ann")
    with pytest.raises(IntegrityError):
        with write_session(engine) as s:
            for k in ("a", "b"):
                s.add(Review(item_id=items[0], reviewer_id=ann.id, decision="accept", values={}, edited=[],
                             idempotency_key=k))
                s.flush()


def test_same_decision_twice_is_harmless(engine, people, items, settings):
    v1, replay1 = decide(engine, "ann", items[0], settings, key="k1")
    v2, replay2 = decide(engine, "ann", items[0], settings, key="k1")
    v3, replay3 = decide(engine, "ann", items[0], settings, key="k2")  # same content, new key
    assert (v1, replay1) == (1, False) and (v2, replay2) == (1, True) and (v3, replay3) == (1, True)
    assert item(engine, items[0]).n_reviews == 1


def test_a_decision_based_on_an_old_version_is_stale(engine, people, items, settings):
    decide(engine, "ann", items[0], settings, key="k1")
    with pytest.raises(Stale, match="changed since you loaded it"):
        decide(engine, "ann", items[0], settings, key="k2", version=0, decision="flag", reason="blurry")
    v, _ = decide(engine, "ann", items[0], settings, key="k3", version=1, decision="flag", reason="blurry")
    assert v == 2


def test_revise_with_a_bad_value_names_the_field(engine, people, items, settings):
    with pytest.raises(Invalid) as e:
        decide(engine, "ann", items[0], settings, decision="revise", fields={"fail_time_s": 999.0})
    assert e.value.field == "fail_time_s" and "within the episode" in e.value.message
    with pytest.raises(Invalid) as e:
        decide(engine, "ann", items[0], settings, decision="revise", fields={"recovery_level": "L9"})
    assert e.value.field == "recovery_level"
    assert item(engine, items[0]).n_reviews == 0


def test_accepting_a_quarantined_item_asks_for_the_missing_values(engine, people, items, settings):
    quarantined = [i for i in items if item(engine, i).quarantined]
    assert len(quarantined) == 1
    with pytest.raises(Invalid) as e:
        decide(engine, "ann", quarantined[0], settings)
    assert e.value.field == "fail_time_s"
    v, _ = decide(engine, "ann", quarantined[0], settings, decision="revise",
                  fields={"fail_time_s": 1.2, "recovery_level": "L1", "failure_category": "grasp_failure",
                          "recovery_action": "Grasp the bowl again"})
    assert v == 1


def test_disagreement_goes_to_adjudication_of_disputed_fields_only(engine, people, items, settings):
    i = items[0]
    t0 = item(engine, i).proposal["fail_time_s"]
    decide(engine, "ann", i, settings, decision="revise", fields={"recovery_level": "L4", "fail_time_s": t0 + 0.3})
    decide(engine, "bob", i, settings)
    it = item(engine, i)
    # times 0.3 s apart agree (tau 0.5); the level does not
    assert it.status == "conflict" and it.disputed == ["recovery_level"]
    dan = user(engine, "dan")
    with write_session(engine) as s:
        with pytest.raises(Invalid) as e:
            adjudication.adjudicate(s, dan, i, {"idempotency_key": "x", "version": it.version, "rationale": "r",
                                                "fields": {"recovery_level": "L4", "failure_category": "other"}},
                                    settings)
        assert e.value.field == "failure_category"
    with write_session(engine) as s:
        with pytest.raises(Invalid, match="rationale"):
            adjudication.adjudicate(s, dan, i, {"idempotency_key": "x", "version": it.version,
                                                "fields": {"recovery_level": "L4"}}, settings)
    with write_session(engine) as s:
        adjudication.adjudicate(s, dan, i, {"idempotency_key": "x", "version": it.version,
                                            "rationale": "the box now blocks the plate", "fields": {"recovery_level": "L4"}},
                                settings)
    it = item(engine, i)
    assert it.status == "final" and it.resolution == "adjudicated"
    assert it.final["recovery_level"] == "L4" and it.final["fail_time_s"] == round(t0 + 0.15, 3)


def test_a_reviewer_of_the_item_cannot_adjudicate_it(engine, people, items, settings):
    from pipeline.review.auth import add_user

    add_user(engine, "ann", "adjudicator")  # ann becomes an adjudicator after reviewing
    decide(engine, "ann", items[0], settings, decision="flag", reason="two failures")
    decide(engine, "bob", items[0], settings)
    it = item(engine, items[0])
    assert it.status == "conflict" and set(it.disputed) == {"fail_time_s", "recovery_level", "failure_category",
                                                             "recovery_action"}
    with write_session(engine) as s:
        with pytest.raises(Forbidden):
            adjudication.claim(s, user(engine, "ann"), items[0])


def test_final_items_are_immutable_and_a_new_revision_reenters_the_queue(engine, people, items, settings):
    i = items[0]
    decide(engine, "ann", i, settings)
    decide(engine, "bob", i, settings)
    final = item(engine, i)
    with pytest.raises(Stale, match="no longer takes reviews"):
        decide(engine, "ann", i, settings, key="again", version=1, decision="flag", reason="changed my mind")
    with write_session(engine) as s:
        with pytest.raises(Stale, match="final"):
            adjudication.adjudicate(s, user(engine, "dan"), i, {"idempotency_key": "z", "version": final.version,
                                                                "rationale": "r", "fields": {}}, settings)
    with write_session(engine) as s:
        new, created = enqueue(s, key=final.key, instruction=final.instruction,
                               proposal={**final.proposal, "recovery_level": "L2"}, context=final.context,
                               required_reviews=2)
    assert created and new.revision == 2 and new.status == "pending"
    again = item(engine, i)
    assert (again.status, again.final, again.version) == ("final", final.final, final.version)


def test_enqueueing_the_same_proposal_again_changes_nothing(engine, items):
    it = item(engine, items[0])
    with write_session(engine) as s:
        same, created = enqueue(s, key=it.key, instruction=it.instruction, proposal=it.proposal,
                                context=it.context, required_reviews=2)
    assert not created and same.id == it.id


def test_leases_expire_so_an_absent_reviewer_holds_nothing(engine, people, items, settings):
    short = workflow.QueueSettings(required_reviews=2, lease_seconds=600)
    with write_session(engine) as s:
        got = [workflow.lease_next(s, user(engine, n), short).id for n in ("ann", "bob")]
    assert got[0] == got[1]  # both reviewers of the same item
    with write_session(engine) as s:
        assert workflow.lease_next(s, user(engine, "cat"), short).id != got[0]  # full
    with write_session(engine) as s:  # ann and bob walk away: their leases run out
        for lease in s.scalars(select(Lease).where(Lease.item_id == got[0])):
            lease.expires_at = 0.0
    with write_session(engine) as s:
        workflow.expire(s)
    assert item(engine, got[0]).status == "pending"
    with write_session(engine) as s:  # cat still holds the item she got; eve gets the freed one
        assert workflow.lease_next(s, user(engine, "eve"), short).id == got[0]


def test_the_next_items_page_reads_the_open_queue_index_without_a_sort_on_sqlite(tmp_path):
    """`lease_next` takes its page from the partial index of open items, so closed items (not in
    it) and a long queue cost nothing; SQLite's planner keeps to it only while the condition is
    written as the index's own (`db.IS_COLLECTING`), not as an `IN`."""
    from pipeline.review.db import make_engine

    engine = make_engine(f"sqlite:///{tmp_path / 'q.sqlite'}")
    try:
        page = workflow._PAGE.params(offset=0).compile(dialect=engine.dialect, compile_kwargs={"literal_binds": True})
        with engine.connect() as c:
            plan = " | ".join(r[-1] for r in c.exec_driver_sql(f"EXPLAIN QUERY PLAN {page}"))
    finally:
        engine.dispose()
    assert "USING INDEX ix_items_queue_open" in plan and "TEMP B-TREE" not in plan, plan
