"""The manifest is rebuilt from done markers; the summary counts per task."""

from __future__ import annotations

import pyarrow as pa
import pytest

from pipeline.atomic import Completions
from pipeline.errors import InputError
from pipeline.records import EpisodeRecord, read_episodes
from pipeline.stage1.summary import collect_records, summarize, write_manifest


def _record(task: str, init: int, success: bool, steps: int) -> EpisodeRecord:
    return EpisodeRecord(
        suite="libero_goal", task=task, task_index=0, instruction="do it", episode_id=f"p-i{init:02d}-s1",
        init_state=init, policy="p", policy_kind="scripted", policy_params={"noise": {"a": 0.1}}, seed=1,
        chunk_size=8, horizon=100, settle_steps=10, steps=steps, success=success, wall_time_s=1.5,
        state_dim=50, path=f"episodes/libero_goal/{task}/p-i{init:02d}-s1",
        videos={} if success else {"agentview": "video_agentview.mp4"}, video_fps=None if success else 10,
    )


def test_manifest_holds_exactly_the_done_episodes_and_round_trips(tmp_path):
    done = Completions(tmp_path)
    recs = [_record("a", 0, True, 40), _record("a", 1, False, 100), _record("b", 0, False, 100)]
    for i, r in enumerate(recs):
        done.mark_done(f"unit{i}", r.model_dump(mode="json"))
    got = collect_records(tmp_path, ["unit0", "unit2", "not_done_yet"])
    assert [r.key for r in got] == sorted([recs[0].key, recs[2].key])
    write_manifest(tmp_path, collect_records(tmp_path))
    assert read_episodes(tmp_path / "episodes.parquet") == sorted(recs, key=lambda r: r.key)


def test_summary_counts_successes_failures_and_mean_steps_per_task():
    rows = summarize([_record("a", 0, True, 40), _record("a", 1, False, 100), _record("b", 0, False, 100)])
    by = {(r["suite"], r["task"]): r for r in rows}
    assert by[("libero_goal", "a")] == {"suite": "libero_goal", "task": "a", "episodes": 2, "successes": 1,
                                             "failures": 1, "mean_steps": 70.0}
    assert by[("all", "")]["episodes"] == 3 and by[("all", "")]["failures"] == 2


def test_a_done_marker_that_is_not_an_episode_record_names_the_marker_and_field(tmp_path):
    done = Completions(tmp_path)
    done.mark_done("unit0", _record("a", 0, True, 40).model_dump(mode="json"))
    done.mark_done("unit1", {**_record("a", 1, False, 100).model_dump(mode="json"), "steps": -3})
    with pytest.raises(InputError) as got:
        collect_records(tmp_path)
    assert got.value.file == str(done.dir / "unit1.done") and got.value.field == "steps"
    assert "unit1.done" in str(got.value) and "steps" in str(got.value)


def test_a_manifest_row_that_is_not_an_episode_record_names_the_file_row_and_field(tmp_path):
    import pyarrow.parquet as pq

    from pipeline.records import episodes_table

    path = write_manifest(tmp_path, [_record("a", 0, True, 40), _record("a", 1, False, 100)])
    table = episodes_table([_record("a", 0, True, 40), _record("a", 1, False, 100)])
    bad = table.set_column(table.schema.get_field_index("control_hz"), "control_hz",
                           pa.array([20, 0], pa.int32()))  # control_hz must be > 0
    pq.write_table(bad, path)
    with pytest.raises(InputError) as got:
        read_episodes(path)
    assert (got.value.file, got.value.field) == (str(path), "row 1.control_hz")
    assert str(path) in str(got.value)
