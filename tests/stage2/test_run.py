"""The stage-2 runner end to end on real rollouts: outcomes, resumability, reports."""

from __future__ import annotations

import json

import pytest

from pipeline.config import Config
from pipeline.errors import FatalError
from pipeline.records import Localization, Phases, QuarantineEntry
from pipeline.stage2.report import write_reports
from pipeline.stage2.run import run



def _outputs(run_dir, kind):
    return {p.stem: p for p in (run_dir / "stage2" / kind).rglob("*.json")}


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_every_failed_episode_ends_with_a_scene_pair_or_a_quarantine_entry(stage2_run, episodes):
    locs, quar = _outputs(stage2_run, "localizations"), _outputs(stage2_run, "quarantine")
    failed = {r.episode_id for r in episodes.values() if not r.success}
    assert set(locs) | set(quar) == failed and not set(locs) & set(quar)
    for ep_id in locs:
        loc = Localization.model_validate_json(locs[ep_id].read_text())
        assert (stage2_run / "stage2" / loc.scene_bddl).exists() and (stage2_run / "stage2" / loc.scene_state).exists()
        assert (stage2_run / "stage2" / loc.evidence).exists()


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_successful_episodes_are_skipped(stage2_run, episodes):
    ok = episodes["success"].episode_id
    assert not list((stage2_run / "stage2").rglob(f"*{ok}*"))


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_an_episode_without_failure_events_is_quarantined_with_a_fallback(stage2_run, episodes):
    entry = QuarantineEntry.model_validate_json(_outputs(stage2_run, "quarantine")[episodes["idle"].episode_id].read_text())
    assert entry.reason == "no_failure_found" and entry.source == "simstate"
    assert entry.fallback_step == 0 and "fallback" in entry.detail
    assert (stage2_run / "stage2" / entry.evidence).exists()  # reviewers still get the evidence


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_compiled_table_summary_and_resolved_config_are_written(stage2_run):
    import pyarrow.parquet as pq

    table = pq.read_table(stage2_run / "stage2" / "localizations.parquet")
    assert table.num_rows == 3 and {"fail_step", "during_end", "onset_kind"} <= set(table.column_names)
    summary = json.loads((stage2_run / "stage2" / "summary.json").read_text())
    assert summary["scenes"] == 3 and summary["quarantine_reasons"] == {"no_failure_found": 1}
    assert (stage2_run / "stage2" / "config.resolved.yaml").exists()
    assert len(list((stage2_run / "stage2" / "_done").glob("*.done"))) == 4


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_rerun_finds_nothing_to_do_and_rewrites_no_episode_output(stage2_run):
    cfg = Config.model_validate({"run": {"output_dir": str(stage2_run)}, "executor": {"workers": 1}})
    files = [p for p in (stage2_run / "stage2").rglob("*") if p.is_file() and p.parent.name != "stage2"]
    before = {p: p.stat().st_mtime_ns for p in files}
    summary = run(cfg)
    assert summary["scenes"] == 3
    assert {p: p.stat().st_mtime_ns for p in files} == before


def test_a_missing_stage1_manifest_is_fatal(tmp_path):
    with pytest.raises(FatalError, match="episodes.parquet"):
        run(Config.model_validate({"run": {"output_dir": str(tmp_path)}}))


def test_agreement_report_compares_vlm_and_simstate_onsets(tmp_path):
    stage2 = tmp_path / "stage2"
    for i, (vlm_t, sim_t) in enumerate([(2.0, 2.2), (3.0, 3.8), (1.0, 3.0), (4.0, None)]):
        loc = Localization(key=f"s/t/e{i}", suite="s", task="t", episode_id=f"e{i}", instruction="x", source="openai",
                           model="qwen", fail_time_s=vlm_t, fail_step=int(vlm_t * 20),
                           phases=Phases(pre=(0, 1), during=(1, 2), post=(2, 3)), scene_bddl="a", scene_state="b",
                           simstate_time_s=sim_t)
        path = stage2 / "localizations" / "s" / "t" / f"e{i}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(loc.model_dump_json())
    summary = write_reports(stage2)
    agr = json.loads((stage2 / "agreement.json").read_text())
    assert agr["n"] == 3 and agr["simstate_missing"] == 1
    assert agr["mae_s"] == pytest.approx((0.2 + 0.8 + 2.0) / 3)
    assert agr["within_0_5s"] == pytest.approx(1 / 3) and agr["within_1s"] == pytest.approx(2 / 3)
    assert (stage2 / "agreement.png").read_bytes()[:4] == b"\x89PNG"
    assert summary["agreement"]["n"] == 3


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_vlm_backend_localizes_over_loopback_and_simstate_runs_beside_it(stage1_run, episodes, tmp_path):
    import shutil

    from pipeline.stage2.vlm_step import run_vlm
    from tests.labelers.vlm.loopback_server import LoopbackServer

    run_dir = tmp_path / "run"
    shutil.copytree(stage1_run, run_dir)
    with LoopbackServer(answer='{"fail": 2.0}') as srv:
        cfg = Config.model_validate({
            "run": {"output_dir": str(run_dir)}, "executor": {"workers": 1},
            "stage2": {"history_frames": 0, "vlm": {"backend": "openai", "language": "en",
                       "openai": {"base_url": srv.base_url, "model": "ok", "max_retries": 0}}}})
        summary = run(cfg)
        # the answers' markers record the localizer: another prompt version asks again
        failed = [r for r in episodes.values() if not r.success]
        v1 = cfg.model_copy(update={"stage2": cfg.stage2.model_copy(
            update={"vlm": cfg.stage2.vlm.model_copy(update={"prompt_version": "v1"})})})
        assert (run_vlm(cfg, failed), run_vlm(v1, failed)) == (0, len(failed))
    drop = Localization.model_validate_json(_outputs(run_dir, "localizations")[episodes["drop"].episode_id].read_text())
    assert (drop.source, drop.model, drop.fail_time_s, drop.fail_step) == ("openai", "ok", 2.0, 40)
    assert drop.raw_text and drop.prompt_hash and drop.simstate_time_s == pytest.approx(5.5, abs=0.5)
    miss = QuarantineEntry.model_validate_json(_outputs(run_dir, "quarantine")[episodes["miss"].episode_id].read_text())
    assert miss.reason == "no_video"  # the fixture rendered videos for drop and knock only
    agr = json.loads((run_dir / "stage2" / "agreement.json").read_text())
    assert agr["n"] == summary["agreement"]["n"] == 2 and agr["mae_s"] > 0
