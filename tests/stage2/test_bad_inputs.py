"""Stage 2 on broken stage-1 input (the cached real rollouts, corrupted in a copy): a
truncated states.npy or steps.parquet, or one bad manifest cell, sets that episode aside as a
quarantine entry naming file, field and reason; the stage goes on with the rest, counts what
it set aside, and picks the fixed files up on the next run."""

from __future__ import annotations

import json
import shutil

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from pipeline.config import Config
from pipeline.errors import EpisodeError
from pipeline.records import EPISODE_SCHEMA, QuarantineEntry, read_episode_rows
from pipeline.stage2.layout import load_episode
from pipeline.stage2.run import run


def truncate(path, keep=0.5):
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def spoil_manifest_cell(manifest, episode_id, field, value):
    rows = pq.read_table(manifest).to_pylist()
    for row in rows:
        if row["episode_id"] == episode_id:
            row[field] = value
    pq.write_table(pa.Table.from_pylist(rows, schema=EPISODE_SCHEMA), manifest)


@pytest.mark.parametrize("name,reason,field", [("states.npy", "stage1_bad_states", "states"),
                                               ("steps.parquet", "stage1_bad_steps", "<file>")])
def test_a_truncated_episode_file_is_an_episode_error_naming_file_and_field(stage1_run, episodes, tmp_path,
                                                                            name, reason, field):
    rec = episodes["drop"]
    shutil.copytree(stage1_run / "stage1" / rec.path, tmp_path / rec.path)
    truncate(tmp_path / rec.path / name)
    with pytest.raises(EpisodeError) as e:
        load_episode(tmp_path, rec)
    assert (e.value.reason, e.value.field) == (reason, field) and e.value.file.endswith(name)


def test_one_bad_manifest_cell_sets_that_row_aside_and_reads_the_others(stage1_run, episodes, tmp_path):
    manifest = tmp_path / "episodes.parquet"
    shutil.copy(stage1_run / "stage1" / "episodes.parquet", manifest)
    spoil_manifest_cell(manifest, episodes["miss"].episode_id, "policy_params", "{oops")
    spoil_manifest_cell(manifest, episodes["idle"].episode_id, "control_hz", 0)
    spoil_manifest_cell(manifest, episodes["success"].episode_id, "suite", "")
    good, bad = read_episode_rows(manifest)
    assert len(good) == len(episodes) - 3
    bad = {b.field: b for b in bad}
    assert bad["policy_params"].key == episodes["miss"].key and bad["policy_params"].success is False
    assert bad["control_hz"].key == episodes["idle"].key
    assert bad["suite"].key.startswith("unknown_suite/") and bad["suite"].success is True  # a success: skipped


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_bad_episode_inputs_are_set_aside_and_picked_up_once_fixed(stage1_run, episodes, tmp_path):
    run_dir = tmp_path / "run"
    shutil.copytree(stage1_run, run_dir)
    s1 = run_dir / "stage1"
    drop, knock, miss = episodes["drop"], episodes["knock"], episodes["miss"]
    truncate(s1 / drop.path / "states.npy")
    truncate(s1 / knock.path / "steps.parquet")
    spoil_manifest_cell(s1 / "episodes.parquet", miss.episode_id, "policy_params", "{oops")
    cfg = Config.model_validate({"run": {"output_dir": str(run_dir)}, "executor": {"workers": 1},
                                 "stage2": {"history_frames": 0}})

    summary = run(cfg)  # the landed code stopped here with a ValueError from np.load

    quar = {p.stem: QuarantineEntry.model_validate_json(p.read_text())
            for p in (run_dir / "stage2" / "quarantine").rglob("*.json")}
    want = {drop.episode_id: ("stage1_bad_states", f"stage1/{drop.path}/states.npy", "states"),
            knock.episode_id: ("stage1_bad_steps", f"stage1/{knock.path}/steps.parquet", "<file>"),
            miss.episode_id: ("stage1_bad_manifest", "stage1/episodes.parquet", "policy_params")}
    for ep_id, (reason, file, field) in want.items():
        assert (quar[ep_id].reason, quar[ep_id].file, quar[ep_id].field) == (reason, file, field)
    assert quar[episodes["idle"].episode_id].reason == "no_failure_found"  # the rest went on
    assert summary["set_aside"] == 3 and summary["scenes"] == 0
    on_disk = json.loads((run_dir / "stage2" / "summary.json").read_text())
    assert {f["key"] for f in on_disk["input_faults"]} == {drop.key, knock.key, miss.key}

    for rec in (drop, knock):  # the fixed files: fresh copies of the originals
        shutil.copy2(stage1_run / "stage1" / rec.path / "states.npy", s1 / rec.path / "states.npy")
        shutil.copy2(stage1_run / "stage1" / rec.path / "steps.parquet", s1 / rec.path / "steps.parquet")
    shutil.copy2(stage1_run / "stage1" / "episodes.parquet", s1 / "episodes.parquet")
    summary = run(cfg)
    assert summary["set_aside"] == 0 and summary["scenes"] == 3
    assert {p.stem for p in (run_dir / "stage2" / "quarantine").rglob("*.json")} == {episodes["idle"].episode_id}


def test_a_manifest_that_cannot_be_read_at_all_is_fatal_and_named(tmp_path):
    from pipeline.errors import FatalError

    (tmp_path / "stage1").mkdir()
    (tmp_path / "stage1" / "episodes.parquet").write_bytes(b"PAR1 cut short")
    with pytest.raises(FatalError, match="episodes.parquet: unreadable stage 1 manifest"):
        run(Config.model_validate({"run": {"output_dir": str(tmp_path)}}))


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_stored_vlm_answer_that_does_not_read_sets_only_its_episode_aside_naming_the_file(stage1_run, episodes,
                                                                                            tmp_path):
    from pipeline.layout import RunLayout
    from pipeline.stage2.vlm_step import run_vlm
    from tests.labelers.vlm.loopback_server import LoopbackServer

    run_dir = tmp_path / "run"
    shutil.copytree(stage1_run, run_dir)
    paths = RunLayout(run_dir).stage2
    failed = [r for r in episodes.values() if not r.success]
    good, bad = episodes["drop"], episodes["miss"]
    with LoopbackServer(answer='{"fail": 5.5}') as srv:  # every answer stored (and marked): the run asks no server
        cfg = Config.model_validate({"run": {"output_dir": str(run_dir)}, "executor": {"workers": 1},
                                     "stage2": {"history_frames": 0, "vlm": {
                                         "backend": "openai", "language": "en",
                                         "openai": {"base_url": srv.base_url, "model": "ok", "max_retries": 0}}}})
        assert run_vlm(cfg, failed) == len(failed)
    paths.abs(paths.vlm(bad)).write_text('{"source": "openai", "fail_time_s": ')  # cut off mid-write
    run(cfg)
    q = QuarantineEntry.model_validate_json(paths.abs(paths.quarantine(bad)).read_text())
    assert q.reason == "episode_error" and str(paths.abs(paths.vlm(bad))) in q.detail
    loc = json.loads(paths.abs(paths.localization(good)).read_text())
    assert (loc["source"], loc["fail_time_s"], loc["model"]) == ("openai", 5.5, "ok")
