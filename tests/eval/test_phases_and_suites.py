"""Issue 24 parity: RD starts in three phases from stage 2's split, M_during beside M_pre /
M_post, and LIBERO-100 reported beside its halves, pooled from trials. No simulator."""

from __future__ import annotations

import json

from pipeline.config import EvalConfig
from pipeline.eval.metrics import rd
from pipeline.eval.rd import at_onset, stage2_phases, start_steps
from pipeline.eval.report import write_report
from pipeline.records import PhaseFields
from tests.eval.test_metrics import row


def test_rd_starts_carry_stage2s_three_phases():
    phases = PhaseFields(pre=(0, 45), during=(45, 70), post=(70, 101))
    assert start_steps(101, onset=45, every=20, phases=phases) == [
        (0, "pre"), (20, "pre"), (40, "pre"), (60, "during"), (80, "post"), (100, "post")]


def test_phases_follow_a_reviewed_onset():
    phases = PhaseFields(pre=(0, 45), during=(45, 70), post=(70, 101))
    assert at_onset(phases, 30, 101) == PhaseFields(pre=(0, 30), during=(30, 70), post=(70, 101))
    assert at_onset(phases, 80, 101) == PhaseFields(pre=(0, 80), during=(80, 81), post=(81, 101))


def test_stage2_phases_are_read_from_the_localization_or_none(tmp_path):
    assert stage2_phases(tmp_path, "libero_goal/t/ep") is None
    loc = tmp_path / "localizations/libero_goal/t/ep.json"
    loc.parent.mkdir(parents=True)
    loc.write_text("{}")
    try:
        stage2_phases(tmp_path, "libero_goal/t/ep")
    except ValueError as e:
        assert str(loc) in str(e)
    else:
        raise AssertionError("a broken localization was read")


def test_rd_reports_m_during_from_the_matched_scenes():
    rows = [row(True, mode="rd", rd_phase="pre", scene="s"), row(False, mode="rd", rd_phase="post", scene="s"),
            row(True, mode="rd", rd_phase="during", scene="s"), row(False, mode="rd", rd_phase="during", scene="s"),
            row(True, mode="rd", rd_phase="during", scene="unmatched")]
    r = rd(rows, 1e-3)
    assert (r.m_pre, r.m_during, r.m_post, r.n_during, r.scenes) == (1.0, 0.5, 0.0, 2, 1)


def test_libero_100_is_pooled_from_trials_beside_its_halves(tmp_path):
    # libero_10: 1 of 1; libero_90: 1 of 3. Pooled: 2 of 4 = 50 %, where averaging would say 66.7 %
    rows = [row(True, suite="libero_10")] + [row(w, suite="libero_90") for w in (True, False, False)]
    rows += [row(True, suite="libero_goal")]
    rows += [row(True, suite="libero_90", mode="rd", rd_phase=p, scene="s") for p in ("pre", "during")]
    rows += [row(False, suite="libero_90", mode="rd", rd_phase="post", scene="s")]
    data = write_report(rows, EvalConfig(), tmp_path)
    grid = data["policies"]["scripted"]["rsr_suite_level"]
    assert list(grid) == ["libero_goal", "libero_10", "libero_90", "libero_100"]
    assert grid["libero_100"]["all"] == 0.5
    md = (tmp_path / "report.md").read_text()
    assert "| *libero_100* | 50.0 (4) | — | — | — | 50.0 (4) |" in md
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["policies"]["scripted"]["rd"]["libero_100"]["m_during"] == 1.0
    assert "| suite | M_pre | M_during | M_post | RD |" in md
    assert (tmp_path / "rd_phases.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_each_policy_entry_runs_with_its_own_temporal_context_and_gets_a_report_row(tmp_path):
    from pathlib import Path

    from pipeline.config import Config
    from pipeline.eval.plan import plan_trials
    from pipeline.eval.scenes import Scene

    names = {"pi-none": "none", "pi-initial": "initial_frame", "pi-history": "history"}
    cfg = Config.model_validate({"run": {"output_dir": str(tmp_path)}, "eval": {
        "rd": False, "trials_per_condition": 1, "gripper_conditions": ["open"], "temporal_context": "initial_frame",
        "policies": [{"kind": "openpi", "name": "pi-none", "temporal_context": "none"},
                     {"kind": "openpi", "name": "pi-initial"},  # eval.temporal_context
                     {"kind": "openpi", "name": "pi-history", "temporal_context": "history"}]}})
    scene = Scene("libero_goal", "t", "scripted-i00-s0", 40, Path("s.bddl"), Path("s.npy"))
    trials, _ = plan_trials(cfg, [scene])
    assert {t.policy: t.temporal_context for t in trials} == names
    write_report([row(True, policy=n) for n in names], cfg.eval, tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert "| policy | kind | temporal context |" in md
    for name, ctx in names.items():
        assert f"| `{name}` | — | {ctx} |" in md


def test_rd_of_a_merged_runs_scene_reads_that_runs_rollout_and_stage2_phases(tmp_path):
    """A scene released from `release.merge_runs`: its RD starts come from its own run's
    stage 1, labelled by its own run's stage-2 phases (moved to the reviewed onset)."""
    from pathlib import Path

    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from pipeline.config import Config
    from pipeline.eval.plan import plan_trials
    from pipeline.eval.scenes import Scene
    from pipeline.layout import RunLayout
    from pipeline.records import Localization, Phases

    other = RunLayout(tmp_path / "other")
    key = "libero_goal/t/noisy-i00-s0"
    folder = other.stage1.episode_dir(key)
    folder.mkdir(parents=True)
    np.save(folder / "states.npy", np.zeros((101, 5)))
    pq.write_table(pa.table({"action": [[0.0] * 7] * 100}), folder / "steps.parquet")
    loc = other.stage2.localization_of_key(key)
    loc.parent.mkdir(parents=True)
    loc.write_text(Localization(key=key, suite="libero_goal", task="t", episode_id="noisy-i00-s0", instruction="i",
                                source="simstate", fail_time_s=2.25, fail_step=45,
                                phases=Phases(pre=(0, 45), during=(45, 70), post=(70, 101)),
                                scene_bddl="x.bddl", scene_state="x.npy").model_dump_json())
    cfg = Config.model_validate({"run": {"output_dir": str(tmp_path / "main")},
                                 "release": {"merge_runs": [str(other.root)]},
                                 "eval": {"trials_per_condition": 1, "gripper_conditions": ["open"]}})
    scene = Scene("libero_goal", "t", "noisy-i00-s0", 75, Path("s.bddl"), Path("s.npy"), fail_step=50)
    trials, problems = plan_trials(cfg, [scene])
    rd = sorted({(t.rd_start_step, t.rd_phase) for t in trials if t.mode == "rd"})
    assert rd == [(0, "pre"), (20, "pre"), (40, "pre"), (60, "during"), (80, "post"), (100, "post")]
    assert problems == []
