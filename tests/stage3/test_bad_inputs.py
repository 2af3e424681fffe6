"""Stage 3 on stage-2 files it cannot use as they are: each is set aside as a stage-3
quarantine entry naming file, field and reason, queued as a quarantined item (never with
its bad value), counted in the summary; a corrected file is read again on the next run."""

from __future__ import annotations

import json
import math

import pytest
import yaml
from sqlalchemy import select
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.records import QuarantineEntry
from pipeline.review.db import Item, make_engine, read_session
from tests.review.sample_run import SUITE, TASK, build

EP = "scripted-i{:02d}-s0".format
INLINE = {"executor": {"kind": "inline"}}  # about the inputs, not the executor (test_executors.py): no worker to spawn


def _loc_file(run, i):
    return run / "stage2" / "localizations" / SUITE / TASK / f"{EP(i)}.json"


def _edit(run, i, **fields):
    path = _loc_file(run, i)
    data = json.loads(path.read_text())
    data.update(fields)
    path.write_text(json.dumps(data))  # json writes NaN as the bare literal a buggy writer leaves


@pytest.fixture
def bad_run(tmp_path):
    run = tmp_path / "run"
    build(run, n_episodes=5, n_quarantined=0, wrist=False)  # 60 steps at 20 Hz: 3.0 s episodes
    _edit(run, 0, fail_time_s=math.nan)
    _edit(run, 1, fail_time_s=-1.0)
    _edit(run, 2, fail_time_s=99.0)
    _edit(run, 4, key=f"{SUITE}/{TASK}/{EP(3)}", episode_id=EP(3))  # repeats episode 3's key
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "stage3": {"reviews_per_item": 2}, **INLINE}))
    return run, cfg


def _stage3(cfg):
    result = CliRunner().invoke(app, ["stage3", "--config", str(cfg)])
    assert result.exit_code == 0, result.output + repr(result.exception)
    return result.output


def _items(run):
    engine = make_engine(f"sqlite:///{run / 'stage3' / 'review.sqlite'}")
    with read_session(engine) as s:
        items = {}
        for item in s.scalars(select(Item).order_by(Item.revision)):
            items[item.episode_id] = item  # the latest revision wins
    engine.dispose()
    return items


def test_bad_fail_times_and_a_repeated_key_are_set_aside_with_file_field_and_reason(bad_run):
    run, cfg = bad_run
    out = _stage3(cfg)
    items = _items(run)
    assert sorted(items) == [EP(i) for i in range(5)]  # nothing dropped, the repeated key included
    want = {0: "fail_time_not_finite", 1: "fail_time_negative", 2: "fail_time_beyond_episode", 4: "duplicate_key"}
    for i, reason in want.items():
        item = items[EP(i)]
        assert item.quarantined and item.quarantine_reason == f"stage3:{reason}"
        assert item.proposal["fail_time_s"] is None  # never queued with the bad value
        q = QuarantineEntry.model_validate_json(
            (run / "stage3" / "quarantine" / SUITE / TASK / f"{EP(i)}.json").read_text())
        assert q.file == f"stage2/localizations/{SUITE}/{TASK}/{EP(i)}.json"
        assert q.field == ("key" if i == 4 else "fail_time_s") and q.field in q.detail
    assert not items[EP(3)].quarantined and items[EP(3)].proposal["fail_time_s"] == pytest.approx(1.8)
    assert EP(3) in items[EP(4)].quarantine_detail  # names the file it collides with
    summary = json.loads((run / "stage3" / "summary.json").read_text())
    assert summary["set_aside"] == 4 and {f["reason"] for f in summary["input_faults"]} == set(want.values())
    assert "4 set aside" in out


def test_a_corrected_localization_is_read_again_on_the_next_run(bad_run):
    run, cfg = bad_run
    _stage3(cfg)
    _edit(run, 0, fail_time_s=1.5)  # the NaN fixed
    _edit(run, 3, fail_time_s=2.0)  # a valid value corrected
    _stage3(cfg)
    items = _items(run)
    assert not items[EP(0)].quarantined and items[EP(0)].proposal["fail_time_s"] == 1.5
    assert items[EP(3)].proposal["fail_time_s"] == 2.0 and items[EP(3)].revision == 2
    assert not (run / "stage3" / "quarantine" / SUITE / TASK / f"{EP(0)}.json").exists()
    summary = json.loads((run / "stage3" / "summary.json").read_text())
    assert summary["set_aside"] == 3 and summary["skipped"] == 3  # only the two edited files ran again


def test_a_key_that_is_not_its_own_suite_task_and_episode_is_set_aside(tmp_path):
    from pipeline.stage3.inputs import collect

    run = tmp_path / "run"
    build(run, n_episodes=2, n_quarantined=0, wrist=False)
    _edit(run, 1, key="bogus")  # every later step splits the key into suite/task/episode
    units = {u.key: u for u in collect(run)}
    bad = units[f"{SUITE}/{TASK}/{EP(1)}"].quarantine
    assert (bad.reason, bad.field) == ("key_mismatch", "key") and "bogus" in bad.detail
    assert units[f"{SUITE}/{TASK}/{EP(0)}"].localization is not None and "bogus" not in units


def test_an_unreadable_frame_table_is_reported_by_name_and_the_duration_comes_from_the_evidence(tmp_path, caplog):
    from pipeline.stage3.inputs import collect, context

    run = tmp_path / "run"
    build(run, n_episodes=1, n_quarantined=0, wrist=False)
    frames = run / "stage1" / "episodes" / SUITE / TASK / EP(0) / "frames.parquet"
    frames.write_bytes(b"not parquet")
    [unit] = collect(run)
    with caplog.at_level("WARNING", logger="pipeline.stage3"):
        ctx = context(run, unit, 20, 10.0)
    assert ctx["duration_s"] is not None  # the evidence's last step
    assert any(str(frames) in r.getMessage() and "unreadable" in r.getMessage() for r in caplog.records)


def test_a_bug_while_reading_media_is_not_swallowed(tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    from pipeline.stage3.inputs import collect, context

    run = tmp_path / "run"
    build(run, n_episodes=1, n_quarantined=0, wrist=False)
    [unit] = collect(run)

    def broken(*a, **k):
        raise TypeError("a programming error, not a bad file")

    monkeypatch.setattr(pq, "read_table", broken)
    with pytest.raises(TypeError):
        context(run, unit, 20, 10.0)


def test_a_proposal_the_queue_refuses_is_set_aside_naming_file_and_field(tmp_path):
    run = tmp_path / "run"
    build(run, n_episodes=2, n_quarantined=0, wrist=False)
    _edit(run, 0, fail_step=-1)  # a time the checks pass, a step no video has
    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"run": {"output_dir": str(run)}, "stage3": {"reviews_per_item": 2}, **INLINE}))
    _stage3(cfg)
    items = _items(run)
    assert items[EP(0)].quarantined and items[EP(0)].quarantine_reason == "stage3:bad_proposal"
    assert items[EP(0)].proposal["fail_step"] is None and items[EP(0)].proposal["localizer"]["source"] == "simstate"
    assert not items[EP(1)].quarantined
    q = QuarantineEntry.model_validate_json((run / "stage3" / "quarantine" / SUITE / TASK / f"{EP(0)}.json").read_text())
    assert (q.reason, q.file, q.field) == ("bad_proposal", f"stage2/localizations/{SUITE}/{TASK}/{EP(0)}.json",
                                           "proposal.fail_step")
    summary = json.loads((run / "stage3" / "summary.json").read_text())
    assert summary["set_aside"] == 1 and summary["input_faults"][0]["field"] == "proposal.fail_step"
