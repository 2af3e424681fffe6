from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.eval.scenes import find_scenes


def _scene(root: Path, suite="libero_spatial", task="pick_x", ep="scripted-i03-s7", step=42, state=True) -> Path:
    d = root / f"selected_bddl_scenes_{suite}" / task / f"episode_{ep}"
    d.mkdir(parents=True, exist_ok=True)
    bddl = d / f"step_{step:04d}.bddl"
    bddl.write_text("(define (problem x))\n")
    if state:
        np.save(d / f"step_{step:04d}_sim_state.npy", np.zeros(5))
    return bddl


def test_layout_scenes_are_found_with_suite_task_episode_and_step(tmp_path):
    _scene(tmp_path, step=42)
    _scene(tmp_path, suite="libero_goal", task="open_y", ep="e1", step=7)
    scenes, problems = find_scenes(tmp_path)
    assert problems == []
    assert [s.scene_id for s in scenes] == ["libero_goal/open_y/e1/step_0007",
                                             "libero_spatial/pick_x/scripted-i03-s7/step_0042"]
    s = scenes[1]
    assert (s.suite, s.task, s.episode_id, s.step, s.level) == ("libero_spatial", "pick_x", "scripted-i03-s7", 42, None)
    assert s.state_path.name == "step_0042_sim_state.npy"


def test_a_bddl_without_its_state_is_reported_by_name_and_skipped(tmp_path):
    bddl = _scene(tmp_path, state=False)
    _scene(tmp_path, ep="ok")
    scenes, problems = find_scenes(tmp_path)
    assert [s.episode_id for s in scenes] == ["ok"]
    assert len(problems) == 1 and str(bddl) in problems[0] and "no state file" in problems[0]


def test_a_missing_scene_folder_fails_naming_it(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere"):
        find_scenes(tmp_path / "nowhere")


def test_a_release_manifest_supplies_levels_and_categories(tmp_path):
    from pipeline.release.manifest import ScenarioRow, write_manifest

    bddl = _scene(tmp_path, step=42)
    state = bddl.with_name("step_0042_sim_state.npy")
    row = ScenarioRow(
        suite="libero_spatial", task="pick_x", instruction="pick x", episode_id="scripted-i03-s7", init_state=3,
        step=42, fail_time_s=2.1, fail_step=42, level="L2", category="grasp_failure", recovery_action="regrasp",
        policy="scripted", policy_kind="scripted", seed=7, state_dim=5,
        bddl_path=str(bddl.relative_to(tmp_path)), bddl_sha256="x", state_path=str(state.relative_to(tmp_path)),
        state_sha256="y")
    write_manifest(tmp_path / "scenarios.parquet", [row])
    _scene(tmp_path, ep="not_in_manifest")
    scenes, problems = find_scenes(tmp_path)
    assert problems == [] and len(scenes) == 1
    s = scenes[0]
    assert (s.level, s.category, s.init_state, s.instruction) == ("L2", "grasp_failure", 3, "pick x")
