"""`recover stage3` on a small real run folder, then reviews, export, status and history."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml
from sqlalchemy import func, select
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.records import Annotation, Characterization, QuarantineEntry
from pipeline.review.db import Item, User, make_engine, read_session, write_session
from pipeline.review.workflow import QueueSettings, submit_review
from tests.review.sample_run import SUITE, TASK, build

runner = CliRunner()


@pytest.fixture
def smoke_run(tmp_path) -> tuple[Path, Path]:
    run = tmp_path / "run"
    build(run, n_episodes=4, n_quarantined=1, wrist=False)
    # one localized episode whose evidence is missing: its characterization fails
    (run / "stage2" / "evidence" / SUITE / TASK / "scripted-i03-s0.parquet").unlink()
    # one localization file that does not parse
    bad = run / "stage2" / "localizations" / SUITE / TASK / "scripted-i09-s0.json"
    bad.write_text(json.dumps({"key": f"{SUITE}/{TASK}/scripted-i09-s0", "fail_time_s": "soon"}))
    cfg = tmp_path / "smoke.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"name": "t", "output_dir": str(run)},
                                   "tasks": {"suites": ["libero_spatial"], "init_states": [0]},
                                   "stage3": {"reviews_per_item": 2}}))
    return run, cfg


def invoke(*args: str):
    result = runner.invoke(app, list(args))
    assert result.exit_code == 0, result.output + repr(result.exception)
    return result.output


def test_stage3_fills_the_queue_and_marks_quarantined_items(smoke_run):
    run, cfg = smoke_run
    invoke("stage3", "--config", str(cfg))
    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    with read_session(engine) as s:
        items = {i.episode_id: i for i in s.scalars(select(Item))}
    assert sorted(items) == [f"scripted-i0{i}-s0" for i in range(5)] + ["scripted-i09-s0"]
    assert all(i.status == "pending" for i in items.values())
    assert {e for e, i in items.items() if not i.quarantined} == {"scripted-i00-s0", "scripted-i01-s0", "scripted-i02-s0"}
    assert items["scripted-i03-s0"].quarantine_reason == "stage3:missing_evidence"
    assert items["scripted-i03-s0"].proposal["fail_time_s"] is not None  # the localization is kept
    assert items["scripted-i04-s0"].quarantine_reason == "stage2:no_json"
    assert items["scripted-i09-s0"].quarantine_reason == "stage3:unreadable"
    assert "fail_time_s" in items["scripted-i09-s0"].quarantine_detail  # names the field
    ch = Characterization.model_validate_json(
        (run / "stage3" / "characterizations" / SUITE / TASK / "scripted-i00-s0.json").read_text())
    assert ch.source == "simstate" and items["scripted-i00-s0"].proposal["recovery_level"] == ch.recovery_level.value
    q = QuarantineEntry.model_validate_json((run / "stage3" / "quarantine" / SUITE / TASK / "scripted-i03-s0.json").read_text())
    assert q.stage == "stage3" and q.reason == "missing_evidence"
    ctx = items["scripted-i00-s0"].context
    assert ctx["videos"] == {"agentview": f"stage1/episodes/{SUITE}/{TASK}/scripted-i00-s0/video_agentview.mp4"}
    assert ctx["fps"] == 10 and ctx["duration_s"] == 3.0 and ctx["phases"]["pre"][0] == 0

    # a rerun finds everything done and adds nothing
    invoke("stage3", "--config", str(cfg))
    with read_session(engine) as s:
        assert s.scalar(select(func.count(Item.id))) == 6
    assert json.loads((run / "stage3" / "summary.json").read_text())["skipped"] == 6


def test_reviews_then_export_write_final_json_only(smoke_run, tmp_path):
    run, cfg = smoke_run
    invoke("stage3", "--config", str(cfg))
    for name in ("ann", "bob"):
        assert "token:" in invoke("review", "add-reviewer", name, "--config", str(cfg))
    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    settings = QueueSettings()
    with read_session(engine) as s:
        users = {u.name: u for u in s.scalars(select(User))}
        open_items = [i.id for i in s.scalars(select(Item).where(Item.quarantined.is_(False)).order_by(Item.id))]
    for n, item_id in enumerate(open_items):
        for name in ("ann", "bob"):
            # the last item gets two different levels: it stays in conflict, so it is not exported
            body = {"decision": "accept", "idempotency_key": f"{name}{item_id}"}
            if n == len(open_items) - 1 and name == "bob":
                body = {"decision": "revise", "fields": {"recovery_level": "L4" if n else "L1"},
                        "idempotency_key": "b"}
            with write_session(engine) as s:
                submit_review(s, users[name], item_id, body, settings)

    out = invoke("review", "export", "--config", str(cfg))
    root = run / "stage3" / "annotations"
    files = sorted(root.rglob("episode_*.json"))
    assert f"exported {len(open_items) - 1} final record(s)" in out
    assert [f.name for f in files] == ["episode_scripted-i00-s0.json", "episode_scripted-i01-s0.json"]
    a = Annotation.model_validate_json(files[0].read_text())
    assert a.resolution == "agreed" and [r.reviewer for r in a.reviews] == ["ann", "bob"]
    assert a.model_proposal.recovery_level == a.recovery_level and a.fail_step == round(a.fail_time_s * 20)
    table = pq.read_table(root / "annotations.parquet")
    assert table.num_rows == 2 and set(table.column("episode_id").to_pylist()) == {"scripted-i00-s0", "scripted-i01-s0"}

    status = invoke("review", "status", "--config", str(cfg))
    assert "conflict" in status and "final" in status and "kappa" in status.lower()
    png = run / "stage3" / "review_confusion.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((run / "stage3" / "review_status.json").read_text())
    assert summary["counts"]["by_status"] == {"pending": 3, "final": 2, "conflict": 1}
    assert summary["agreement"]["recovery_level"]["percent_agreement"] == pytest.approx(2 / 3, abs=1e-3)

    history = invoke("review", "history", f"{SUITE}/{TASK}/scripted-i00-s0", "--config", str(cfg))
    assert "enqueued" in history and "review" in history and "ann" in history


def test_repo_annotation_schema_matches_the_record():
    from pipeline.review.export import write_schema

    repo = Path(__file__).resolve().parents[2]
    committed = json.loads((repo / "annotations" / "schema.json").read_text())
    fresh = repo / "annotations" / ".schema.check.json"
    try:
        assert json.loads(write_schema(fresh).read_text()) == committed, "run: recover review schema"
    finally:
        fresh.unlink(missing_ok=True)
