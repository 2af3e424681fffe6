"""Writes `review_b67844a.sqlite`: a small review queue made by the code of commit b67844a
(before migrations), for tests/review/test_migrations.py. Run it from a checkout of that
commit, not this one:

    git worktree add --detach /tmp/base b67844a
    cd /tmp/base && PYTHONPATH=$PWD python /path/to/make_base_fixture.py OUT.sqlite

Items: 6 (5 localized + 1 quarantined) with K = 2: one final (agreed), one adjudicated, one
conflict, one with one review and a lease, the rest pending; 4 users; the audit log.
"""

from __future__ import annotations

import sqlite3
import sys
import tempfile
from pathlib import Path

from pipeline.review import adjudication, workflow
from pipeline.review.auth import add_user
from pipeline.review.db import User, make_engine, write_session
from sqlalchemy import select
from tests.review.conftest import fill_queue
from tests.review.sample_run import build


def main(out: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        build(run, n_episodes=5, n_quarantined=1)
        db = run / "stage3" / "review.sqlite"
        engine = make_engine(f"sqlite:///{db}")
        for name, role in [("ann", "reviewer"), ("bob", "reviewer"), ("dan", "adjudicator"), ("eve", "admin")]:
            add_user(engine, name, role)
        ids = fill_queue(run, engine)
        cfg = workflow.QueueSettings(required_reviews=2)

        def decide(name: str, item: int, body: dict) -> None:
            with write_session(engine) as s:
                user = s.scalar(select(User).where(User.name == name))
                workflow.submit_review(s, user, item, {"version": 0, "idempotency_key": f"{name}-{item}", **body}, cfg)

        decide("ann", ids[0], {"decision": "accept"})
        decide("bob", ids[0], {"decision": "accept"})  # final, agreed
        decide("ann", ids[1], {"decision": "accept"})
        decide("bob", ids[1], {"decision": "revise", "fields": {"recovery_level": "L1"}})  # conflict
        decide("ann", ids[2], {"decision": "flag", "reason": "camera blocked"})
        decide("bob", ids[2], {"decision": "revise", "fields": {"failure_category": "grasp_failure"}})
        with write_session(engine) as s:  # adjudicated
            dan = s.scalar(select(User).where(User.name == "dan"))
            item = adjudication.claim(s, dan, ids[2])
            disputed = list(item.disputed)
        with write_session(engine) as s:
            dan = s.scalar(select(User).where(User.name == "dan"))
            item = workflow.get_item(s, ids[2])
            values = {f: (item.agreed or {}).get(f) or item.proposal.get(f) for f in disputed}
            adjudication.adjudicate(s, dan, ids[2], {"fields": values, "rationale": "the bowl tipped",
                                                      "version": item.version, "idempotency_key": "adj"}, cfg)
        decide("ann", ids[3], {"decision": "accept"})
        with write_session(engine) as s:  # bob holds the item ann reviewed
            bob = s.scalar(select(User).where(User.name == "bob"))
            workflow.lease_item(s, bob, workflow.get_item(s, ids[3]), cfg)
        engine.dispose()
        con = sqlite3.connect(db)
        con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        con.execute("PRAGMA journal_mode=DELETE")
        con.execute("VACUUM")
        con.close()
        out.write_bytes(db.read_bytes())


if __name__ == "__main__":
    main(Path(sys.argv[1]))
