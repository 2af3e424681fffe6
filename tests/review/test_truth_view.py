"""Model and reviewers vs the generator's truth in status and export; never on the page."""

from __future__ import annotations

import json

import pyarrow as pa
from sqlalchemy import select

from pipeline.atomic import write_with
from pipeline.policies.scripted.truth import TRUTH_SCHEMA
from pipeline.review import report, truth_view, workflow
from pipeline.review.db import Item, User, read_session, write_session
from pipeline.review.export import export
from tests.review.test_api import client


def write_truth(run_dir, key: str, step: int) -> None:
    """A truth record: the first attempt missed its grasp at `step` (grasp_failure, L1)."""
    suite, task, ep = key.split("/", 2)
    row = {"attempt": 0, "skill": "pick_place", "conjunct": "on akita_black_bowl_1 plate_1",
           "target": "akita_black_bowl_1", "reference": "plate_1", "start_step": 0, "end_step": step + 30,
           "action_noise": 0.2, "speed_factor": 1.0, "subgoal_achieved": False, "outcome": "missed_grasp",
           "event": "close", "event_step": step, "event_object": "akita_black_bowl_1", "knocked": [], "changes": [],
           "detail": ""}
    meta = dict(TRUTH_SCHEMA.metadata)
    meta[b"truth"] = json.dumps({"objects": ["akita_black_bowl_1", "plate_1"], "fixtures": ["main_table"],
                                 "goal": [["on", "akita_black_bowl_1", "plate_1"]], "error": None}).encode()
    table = pa.Table.from_pylist([row], schema=TRUTH_SCHEMA.with_metadata(meta))
    import pyarrow.parquet as pq

    path = run_dir / "stage1" / "episodes" / suite / task / ep / "truth.parquet"
    write_with(path, lambda p: pq.write_table(table, p))


def truths_for_queue(run_dir, engine) -> list[Item]:
    """Truth at the model's onset for the first two localized items, 2 s later for the rest."""
    with read_session(engine) as s:
        items = [i for i in report.current_items(s) if not i.quarantined]
    for n, it in enumerate(items):
        write_truth(run_dir, it.key, it.proposal["fail_step"] + (0 if n < 2 else 40))
    return items


def test_status_figures_put_the_model_and_the_final_records_beside_the_truth(run_dir, engine, people, items,
                                                                             settings, tmp_path):
    assert truth_view.compare(truths_for_queue(run_dir, engine)[:0], run_dir, 0.5) is None
    with read_session(engine) as s:
        assert truth_view.compare(report.current_items(s), tmp_path, 0.5) is None  # a run without truth
        users = {u.name: u for u in s.scalars(select(User))}
    first = items[0]
    for name in ("ann", "bob"):  # both reviewers correct the first item to what the truth says
        body = {"decision": "revise", "fields": {"recovery_level": "L1", "failure_category": "grasp_failure"},
                "idempotency_key": name}
        with write_session(engine) as s:
            workflow.submit_review(s, users[name], first, body, settings)
    with read_session(engine) as s:
        out = truth_view.compare(report.current_items(s), run_dir, settings.time_tolerance_s)
        model, final = out["model"], out["final"]
        assert model["n"] == 5 and model["onset_within_tau"] == 0.4 and model["onset_mae_s"] == 1.2
        assert model["level_agreement"] == 0.0 and model["category_agreement"] == 0.0  # the model said L3 displacement
        assert final["n"] == 1 and final["level_agreement"] == 1.0 and final["onset_within_tau"] == 1.0
        written = export(s, tmp_path / "annotations", run_dir=run_dir, tau=settings.time_tolerance_s)
    assert len(written) == 1
    saved = json.loads((tmp_path / "annotations" / "model_vs_truth.json").read_text())
    assert saved["final"]["category_agreement"] == 1.0 and len(saved["episodes"]) == 1


def test_the_item_payload_never_carries_the_truth(server, run_dir, engine, people, items):
    truths_for_queue(run_dir, engine)
    ann = client(server, people, "ann")
    for item_id in items:
        view = ann.get(f"/api/items/{item_id}").json()
        text = json.dumps(view)
        assert "truth" not in text and "missed_grasp" not in text
    assert "truth" not in json.dumps(ann.get("/api/queue").json())
