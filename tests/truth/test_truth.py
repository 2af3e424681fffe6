"""The generator's truth of hand-built failures, and `recover bench-localize` scoring against it."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.truth.bench import Prediction, load_truths, score
from pipeline.truth.derive import EpisodeTruth, episode_truth, read_truth

def _truth(run, rec):
    return episode_truth(run / "stage1" / rec.path / "truth.parquet", rec.key, rec.control_hz)


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_stage1_writes_the_truth_beside_the_steps(truth_run):
    run, eps = truth_run
    folder = run / "stage1" / eps["miss"].path
    assert {"states.npy", "steps.parquet", "truth.parquet", "video_agentview.mp4"} <= {p.name for p in folder.iterdir()}


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_a_forced_missed_grasp_has_its_close_command_as_onset(truth_run):
    run, eps = truth_run
    rec = eps["miss"]
    actions = np.asarray(pq.read_table(run / "stage1" / rec.path / "steps.parquet").column("action").to_pylist())
    first_close = int(np.flatnonzero(actions[:, 6] > 0)[0])  # the expert travels open until then
    t = _truth(run, rec)
    assert not rec.success
    assert (t.outcome, t.category, t.level, t.onset_step) == ("missed_grasp", "grasp_failure", "L1", first_close)
    rows, _ = read_truth(run / "stage1" / rec.path / "truth.parquet")
    assert rows[0]["approach_height_m"] == pytest.approx(0.06) and rows[0]["grip_error_m"] > 0.05


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_a_forced_drop_in_transit_has_the_forced_open_as_onset(truth_run):
    run, eps = truth_run
    rec, forced = eps["drop"], eps["drop_step"]
    t = _truth(run, rec)
    rows, _ = read_truth(run / "stage1" / rec.path / "truth.parquet")
    assert forced is not None and not rec.success
    assert (t.outcome, t.event, t.onset_step) == ("dropped", "release", forced)
    # carried off its spot towards the plate: a drop in transit is a grasp failure
    assert rows[0]["release_dist_m"] > 0.10 and t.category == "grasp_failure"
    assert t.level == "L3"  # the bowl fell and lies loose: object state recovery


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_bench_localize_scores_simstate_from_the_cli(truth_run):
    from typer.testing import CliRunner

    from pipeline.cli import app

    run, _ = truth_run
    cfg = run / "bench.yaml"
    cfg.write_text(f"run:\n  output_dir: {run}\n")
    res = CliRunner().invoke(app, ["bench-localize", "--config", str(cfg), "--localizer", "simstate"])
    assert res.exit_code == 0, res.output
    folder = run / "bench" / "localize_simstate"
    report = json.loads((folder / "report.json").read_text())
    assert report["truths"] == 2 and report["failed"] == 2
    assert {r["key"] for r in report["worst"]} == {r["key"] for r in report["episodes"]}
    assert (folder / "confusion_level.png").stat().st_size > 1000 and (folder / "confusion_category.png").is_file()
    assert "| onset MAE |" in (folder / "report.md").read_text()


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_the_openai_backend_goes_through_bench_localize_over_loopback(truth_run, tmp_path):
    from pipeline.config import Config
    from pipeline.truth.bench import run as bench
    from tests.labelers.vlm.loopback_server import LoopbackServer

    run, eps = truth_run
    miss = _truth(run, eps["miss"])
    answer = json.dumps({"fail": miss.onset_time_s + 2.0, "recovery_level": "L1",
                         "failure_category": "grasp_failure", "recovery_action": "Pick the bowl up again"})
    with LoopbackServer(answer=answer) as srv:
        cfg = Config.model_validate({"run": {"output_dir": str(run)}, "stage2": {"vlm": {
            "backend": "openai", "language": "en",
            "openai": {"base_url": srv.base_url, "model": "ok", "max_retries": 0}}}})
        report = bench(cfg, "openai", tmp_path / "bench")
        assert len(srv.seen) == 4  # localize, then characterize, per episode
        again = bench(cfg, "openai", tmp_path / "bench")  # the predictions are the episodes' done markers
    assert len(srv.seen) == 4 and again["episodes"] == report["episodes"]
    by_key = {r["key"]: r for r in report["episodes"]}
    assert by_key[miss.key]["error_s"] == pytest.approx(2.0, abs=0.06)
    assert report["characterized"] == 2 and by_key[miss.key]["pred_category"] == "grasp_failure"
    assert (tmp_path / "bench" / "report.md").is_file()


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_failed_episodes_without_a_truth_are_set_aside_with_the_reason(truth_run, tmp_path):
    run, eps = truth_run
    copy = tmp_path / "run"
    shutil.copytree(run / "stage1", copy / "stage1")
    (copy / "stage1" / eps["drop"].path / "truth.parquet").unlink()  # as an openpi episode has none
    failed, truths, aside = load_truths(copy)
    assert len(failed) == 2 and list(truths) == [eps["miss"].key]
    assert aside[eps["drop"].key].startswith("no_truth") and "truth.parquet" in aside[eps["drop"].key]


def _truths(n: int) -> dict[str, EpisodeTruth]:
    return {f"s/t/e{i}": EpisodeTruth(key=f"s/t/e{i}", onset_step=20 + 7 * i, onset_time_s=(20 + 7 * i) / 20,
                                      category="grasp_failure", level="L1", outcome="missed_grasp", attempt=0,
                                      skill="pick_place", event="close") for i in range(n)}


def test_a_localizer_off_by_2_s_scores_0_within_1_s():
    truths = _truths(6)
    late = {k: Prediction(k, t.onset_step + 40, "L1", "grasp_failure") for k, t in truths.items()}
    r = score(truths, late)
    assert (r["within_1s"], r["within_0_5s"], r["onset_mae_s"]) == (0.0, 0.0, 2.0)
    assert (r["before_truth"], r["at_truth"], r["after_truth"]) == (0, 0, 6)
    assert r["level_accuracy"] == r["category_accuracy"] == 1.0
    early = {k: Prediction(k, t.onset_step - 40) for k, t in truths.items()}
    assert score(truths, early)["within_1s"] == 0.0 and score(truths, early)["before_truth"] == 6


def test_an_exact_localizer_scores_all_within_and_misses_count_against_it():
    truths = _truths(4)
    preds = {k: Prediction(k, t.onset_step, "L2", "placement_failure") for k, t in list(truths.items())[:3]}
    r = score(truths, preds)
    assert (r["within_0_5s"], r["localized"], r["unlocalized"]) == (0.75, 3, 1)
    assert r["level_accuracy"] == 0.0 and r["level_confusion"]["L1"] == {"L1": 0, "L2": 3, "L3": 0, "L4": 0, "none": 1}
    assert r["worst"][0]["error_s"] is None  # a miss is the worst case


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_the_transformers_backend_goes_through_bench_localize_with_a_tiny_qwen(truth_run, tmp_path):
    import importlib.util

    if not all(importlib.util.find_spec(m) for m in ("transformers", "torchvision", "torch")):
        pytest.skip("the `vlm` extra (torch, torchvision, transformers) is not installed")
    from pipeline.labelers.vlm.torch_compat import ensure_torchvision

    ensure_torchvision()
    from pipeline.config import Config
    from pipeline.truth.bench import run as bench
    from tests.labelers.vlm.tiny_qwen import build_tiny_qwen

    run, _ = truth_run
    model = build_tiny_qwen(tmp_path / "qwen", "qwen2_5_vl")
    cfg = Config.model_validate({"run": {"output_dir": str(run)}, "stage2": {"vlm": {
        "backend": "transformers", "language": "en",
        "transformers": {"model_path": str(model), "max_new_tokens": 16}}}})
    report = bench(cfg, "transformers", tmp_path / "bench")
    # random weights answer nonsense: every episode is scored as a miss, with the parser's reason
    assert report["truths"] == 2 and report["localizer"] == "transformers"
    assert report["localized"] + sum(report["unlocalized_reasons"].values()) == 2
    assert (tmp_path / "bench" / "report.json").is_file()


@pytest.mark.sim
@pytest.mark.xdist_group("truth_run")
def test_an_episode_the_localizer_cannot_run_on_is_set_aside_as_a_miss_with_the_reason(truth_run, tmp_path):
    import pyarrow as pa

    from pipeline.config import Config
    from pipeline.truth.bench import run as bench

    run, eps = truth_run
    copy = tmp_path / "run"
    shutil.copytree(run / "stage1", copy / "stage1")
    manifest = copy / "stage1" / "episodes.parquet"
    table = pq.read_table(manifest)
    tasks = ["no_such_task" if e == eps["drop"].episode_id else t
             for e, t in zip(table.column("episode_id").to_pylist(), table.column("task").to_pylist(), strict=True)]
    pq.write_table(table.set_column(table.schema.get_field_index("task"), "task", pa.array(tasks)), manifest)
    cfg = Config.model_validate({"run": {"output_dir": str(copy)}, "executor": {"kind": "inline"}})
    report = bench(cfg, "simstate", tmp_path / "bench")
    by_key = {r["key"]: r for r in report["episodes"]}
    [aside] = [r for r in by_key.values() if "no_such_task" in r["key"]]
    assert aside["pred_step"] is None and aside["reason"].startswith("set aside: KeyError") and "no_such_task" in aside["reason"]
    assert by_key[eps["miss"].key]["pred_step"] is not None  # the other episode goes on
    assert len(list((tmp_path / "bench" / "_done").glob("*.done"))) == 1  # no marker: tried again next time


@pytest.mark.sim
def test_a_handle_that_slips_out_mid_pull_is_let_go_where_the_fingers_left_it(tmp_path):
    """A drawer pull whose handle slipped out of the fingers 9 steps into the pull (found on a
    tuning run: libero_90, init state 4, default noise): the onset is the first state without
    the fingers on the cabinet, not the skill's own let-go 50 steps later."""
    from pipeline.sim import build_env, get_task
    from tests.stage1.default_episode import default_episode

    suite, task = "libero_90", "KITCHEN_SCENE1_open_the_top_drawer_of_the_cabinet"
    env = build_env(get_task(suite, task))
    try:
        folder = default_episode(env, tmp_path, suite, task, 4, 631111876, horizon=240)
    finally:
        env.close()
    rows, _ = read_truth(folder / "truth.parquet")
    first = rows[0]
    skill_let_go = min(p["step"] for p in first["phases"] if p["label"] == "let_go")
    assert (first["outcome"], first["event"]) == ("half_open", "let_go")
    pull = min(p["step"] for p in first["phases"] if p["label"] == "pull")
    assert pull < first["event_step"] < skill_let_go - 20


def test_a_part_skill_lets_go_after_its_preamble_not_at_the_back_off_that_freed_the_hand():
    from pipeline.policies.scripted.truth import skill_let_go

    # libero_90 KITCHEN_SCENE4, init 4: the second attempt opened its hand first (release,
    # back_off), pulled from 363 and let go at 427; the old rule took the preamble's 208
    phases = [("release", 196), ("back_off", 208), ("lift", 223), ("transport", 235), ("tilt", 257),
              ("grip_handle", 349), ("pull", 363), ("let_go", 427), ("back_off", 435)]
    assert skill_let_go(phases, 0) == 427
    assert skill_let_go([("face_drawer", 10), ("push", 30), ("back_off", 60), ("retreat", 70)], 0) == 60
    assert skill_let_go([("release", 0), ("back_off", 12), ("tilt", 20)], None) is None
