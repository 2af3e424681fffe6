from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml

from pipeline.config import load_config
from pipeline.eval import run as eval_run
from pipeline.eval.records import read_episodes
from tests.eval.conftest import HoldPolicy


def _config(tmp_path: Path, fixture_run, **eval_overrides) -> Path:
    raw = {
        "run": {"name": "evaltest", "output_dir": str(tmp_path / "run"), "seed": 0},
        "executor": {"kind": "inline"},  # the patched policy factory lives in this process
        # the plain expert only (the default adds the recovery expert: see the reference test)
        "eval": {"policies": [{"kind": "scripted"}],
                 "scenes_dir": str(fixture_run.scenes), "stage1_dir": str(fixture_run.stage1),
                 "trials_per_condition": 2, "horizon": 6, "gripper_settle_steps": 20,
                 "official_trials": 0} | eval_overrides,
    }
    path = tmp_path / "eval.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


@pytest.fixture
def hold_policies(monkeypatch):
    built: list[HoldPolicy] = []

    def make(cfg):
        built.append(HoldPolicy(cfg.name or cfg.kind))
        return built[-1]

    monkeypatch.setattr("pipeline.policies.factory.make_policy", make)
    yield built
    assert all(p.closed for p in built)  # an inline run releases what it built


@pytest.mark.sim
def test_eval_writes_records_and_report_and_a_rerun_redoes_only_missing_trials(tmp_path, fixture_run, hold_policies):
    cfg = load_config(_config(tmp_path, fixture_run, official_trials=2))
    out = eval_run.run(cfg)
    rows = read_episodes(out / "episodes.parquet")
    scene_rows = [r for r in rows if r.mode == "scene"]
    rd_rows = [r for r in rows if r.mode == "rd"]
    assert len(scene_rows) == 4  # 1 scene x 2 gripper conditions x 2 trials
    assert sorted(r.rd_start_step for r in rd_rows) == [0, 20, 40, 60, 80]
    assert {r.rd_phase for r in rd_rows if r.rd_start_step < 40} == {"pre"}
    assert all(not r.success and r.steps == 6 for r in rows)
    for name in ("report.md", "metrics.json", "rsr_heatmap.png", "gripper.png", "config.resolved.yaml",
                 "quarantine.jsonl"):
        assert (out / name).is_file(), name
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["policies"]["scripted"]["rsr"] == 0.0
    assert metrics["policies"]["scripted"]["rsr_suite_level"]["libero_spatial"]["unlabeled"] == 0.0
    assert "| libero_spatial | — | — | — | — | 0.0 (4) | 0.0 (4) |" in (out / "report.md").read_text()
    official = sorted(r.episode_id for r in rows if r.mode == "official")
    assert official == ["official-i00", "official-i01"]  # eval.official_trials (2) for the one task
    assert metrics["policies"]["scripted"]["libero_success"]["libero_spatial"] == 0.0
    assert "| `scripted` | libero_spatial | 0.0 (2) | 0.0 (4) |" in (out / "report.md").read_text()
    assert (out / "libero_vs_rsr.png").is_file()
    assert len(list((out / "_done").glob("*.done"))) == 11

    acted = sum(len(p.contexts) for p in hold_policies)
    before = pq.read_table(out / "episodes.parquet").drop(["wall_time_s"])
    eval_run.run(cfg)  # everything done: nothing runs again
    assert sum(len(p.contexts) for p in hold_policies) == acted

    victim = next((out / "trials").glob("*__scene__*closed__t1.parquet"))
    victim.unlink()
    (out / "_done" / f"{victim.stem}.done").unlink()
    eval_run.run(cfg)
    assert sum(len(p.contexts) for p in hold_policies) == acted + 1  # horizon 6 < chunk 8: one query
    after = pq.read_table(out / "episodes.parquet").drop(["wall_time_s"])
    assert after.equals(before)  # the redone trial is bit-identical


@pytest.mark.sim
def test_a_scene_with_a_broken_state_is_quarantined_with_its_reason(tmp_path, fixture_run, hold_policies):
    import shutil

    import numpy as np

    scenes = tmp_path / "scenes"
    shutil.copytree(fixture_run.scenes, scenes)
    state = next(scenes.rglob("*_sim_state.npy"))
    np.save(state, np.zeros(7))
    cfg = load_config(_config(tmp_path, fixture_run, scenes_dir=str(scenes), rd=False, trials_per_condition=1))
    out = eval_run.run(cfg)
    lines = [json.loads(x) for x in (out / "quarantine.jsonl").read_text().splitlines()]
    assert len(lines) == 2 and {x["reason"] for x in lines} == {"state_mismatch"}
    assert state.name in lines[0]["detail"]
    assert read_episodes(out / "episodes.parquet") == []


@pytest.mark.sim
def test_recover_eval_runs_the_scripted_policy_on_two_workers(tmp_path, fixture_run):
    cfg_path = _config(tmp_path, fixture_run, trials_per_condition=1, horizon=200, rd_every_steps=40)
    raw = yaml.safe_load(cfg_path.read_text())
    raw["executor"] = {"kind": "local", "workers": 2}
    cfg_path.write_text(yaml.safe_dump(raw))
    recover = Path(sys.executable).with_name("recover")
    proc = subprocess.run([str(recover), "eval", "--config", str(cfg_path)], capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = tmp_path / "run" / "eval"
    rows = read_episodes(out / "episodes.parquet")
    scene_rows = [r for r in rows if r.mode == "scene"]
    assert {r.gripper for r in scene_rows} == {"open", "closed"} and len(rows) == 2 + 3  # RD: 0, 40, 80
    assert {r.policy_kind for r in rows} == {"scripted"}
    # the clean scripted expert recovers this scene from either gripper condition
    assert all(r.success and r.steps < 200 for r in scene_rows)
    assert all(r.init_eef_drift_m < 0.01 for r in rows)
    report = (out / "report.md").read_text()
    assert "## Policy `scripted`" in report and "100.0 (2)" in report


@pytest.mark.sim
def test_the_default_eval_reports_the_recovery_expert_as_a_reference_row_beside_the_plain_expert(tmp_path, fixture_run):
    raw = yaml.safe_load(_config(tmp_path, fixture_run, rd=False, trials_per_condition=1, horizon=300,
                                 gripper_conditions=["closed"]).read_text())
    del raw["eval"]["policies"]  # the default: both experts
    path = tmp_path / "default.yaml"
    path.write_text(yaml.safe_dump(raw))
    out = eval_run.run(load_config(path))
    rows = read_episodes(out / "episodes.parquet")
    assert sorted((r.policy, r.policy_kind) for r in rows) == [("recovery", "recovery"), ("scripted", "scripted")]
    assert all(r.success for r in rows if r.policy == "recovery")  # it recovers from a closed empty gripper
    report = (out / "report.md").read_text()
    assert "| `scripted` | scripted expert (reference) |" in report
    assert "| `recovery` | recovery expert (reference) |" in report and "## Policy `recovery`" in report
