"""Stage 3 with a VLM backend: the real OpenAI client against a loopback server standing in
for the 27B model, answers parsed by the shared loss-free parser."""

from __future__ import annotations

import json

import pytest
import yaml
from sqlalchemy import select

from pipeline.config import load_config
from pipeline.review.db import Item, make_engine, read_session
from pipeline.stage3.run import run as run_stage3
from tests.labelers.vlm.loopback_server import LoopbackServer
from tests.review.sample_run import SUITE, TASK, build

ANSWER = json.dumps({"recovery_level": "l2", "failure_category": "Grasp Failure",
                     "recovery_action": "Grasp the black bowl again"})


def config(tmp_path, scenario: str, base_url: str):
    run = tmp_path / "run"
    build(run, n_episodes=2, n_quarantined=1, wrist=False)
    path = tmp_path / "vlm.yaml"
    path.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "stage3": {"vlm": {
        "backend": "openai", "openai": {"base_url": base_url, "model": scenario, "max_retries": 0}}}}))
    return run, load_config(path)


def items(run) -> dict[str, Item]:
    with read_session(make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")) as s:
        return {i.episode_id: i for i in s.scalars(select(Item))}


def test_vlm_answers_become_proposals_with_model_and_prompt_version(tmp_path):
    with LoopbackServer(answer=ANSWER) as srv:
        run, cfg = config(tmp_path, "ok", srv.base_url)
        summary = run_stage3(cfg)
        assert len(srv.seen) == 2 and "black bowl" in srv.seen[0].text
    assert summary["characterized"] == 2 and summary["quarantined_stage2"] == 1
    it = items(run)["scripted-i00-s0"]
    p = it.proposal
    assert (p["recovery_level"], p["failure_category"], p["recovery_action"]) == ("L2", "grasp_failure",
                                                                                  "Grasp the black bowl again")
    assert p["characterizer"]["source"] == "openai" and p["characterizer"]["model"] == "ok"
    assert p["characterizer"]["prompt_name"] and len(p["characterizer"]["prompt_hash"]) >= 8
    assert p["localizer"]["source"] == "simstate"


@pytest.mark.parametrize("scenario, reason", [("length", "truncated"), ("error500", "backend_error")])
def test_unusable_vlm_answers_are_quarantined_and_still_enter_the_queue(tmp_path, scenario, reason):
    with LoopbackServer(answer=ANSWER) as srv:
        run, cfg = config(tmp_path, scenario, srv.base_url)
        summary = run_stage3(cfg)
    assert summary["quarantined_stage3"] == 2
    it = items(run)["scripted-i01-s0"]
    assert it.quarantined and it.quarantine_reason == f"stage3:{reason}" and it.status == "pending"
    assert it.proposal["recovery_level"] is None and it.proposal["fail_time_s"] == 1.6
    entry = json.loads((run / "stage3" / "quarantine" / SUITE / TASK / "scripted-i01-s0.json").read_text())
    assert entry["reason"] == reason and entry["stage"] == "stage3"
    if scenario == "length":
        assert "failure starts" in entry["raw_text"]  # the raw output is kept for people


def test_a_new_characterizer_makes_new_revisions_and_leaves_final_records_alone(tmp_path):
    from pipeline.review.auth import add_user
    from pipeline.review.db import User, write_session
    from pipeline.review.workflow import QueueSettings, submit_review

    run = tmp_path / "run"
    build(run, n_episodes=2, n_quarantined=1, wrist=False)
    first = load_config_for(tmp_path, run, {"backend": "simstate"})
    run_stage3(first)
    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    for name in ("ann", "bob"):
        add_user(engine, name, "reviewer")
    final_id = items(run)["scripted-i00-s0"].id
    with read_session(engine) as s:
        users = {u.name: u for u in s.scalars(select(User))}
    for name in ("ann", "bob"):
        with write_session(engine) as s:
            submit_review(s, users[name], final_id, {"decision": "accept", "idempotency_key": name}, QueueSettings())
    with LoopbackServer(answer=ANSWER) as srv:
        second = load_config_for(tmp_path, run, {"backend": "openai", "openai": {"base_url": srv.base_url, "model": "ok"}})
        summary = run_stage3(second)
    assert summary["characterized"] == 2 and summary["skipped"] == 0
    with read_session(engine) as s:
        rows = s.scalars(select(Item).where(Item.episode_id == "scripted-i00-s0").order_by(Item.revision)).all()
        quarantined = s.scalars(select(Item).where(Item.episode_id == "scripted-i02-s0")).all()
    assert [(r.revision, r.status) for r in rows] == [(1, "final"), (2, "pending")]
    assert rows[0].final["recovery_level"] == rows[0].proposal["recovery_level"] != rows[1].proposal["recovery_level"]
    assert len(quarantined) == 1  # the stage-2 quarantine proposal did not change: no new revision


def load_config_for(tmp_path, run, vlm: dict):
    path = tmp_path / f"cfg-{vlm['backend']}.yaml"
    path.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "stage3": {"vlm": vlm},
                                    "executor": {"kind": "inline"}}))  # the tests above run the VLM in a worker
    return load_config(path)
