from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pipeline.errors import EpisodeError
from pipeline.eval.protocol import Trial, run_trial
from pipeline.eval.records import EvalEpisode, read_episodes, write_episodes
from pipeline.eval.scenes import find_scenes
from tests.eval.conftest import HoldPolicy


@pytest.fixture(scope="module")
def scene(fixture_run):
    return find_scenes(fixture_run.scenes)[0][0]


def _trial(scene, **kw) -> Trial:
    base = dict(scene=scene, policy="hold", policy_kind="test", gripper="open", trial=0, seed=0, chunk_size=8,
                horizon=12, max_offset_m=0.02, gripper_settle_steps=20)
    return Trial(**(base | kw))


@pytest.mark.sim
def test_a_trial_records_its_trajectory_and_fails_when_the_goal_is_never_met(scene_env, scene, tmp_path):
    ep = run_trial(scene_env, HoldPolicy(), _trial(scene))
    assert not ep.success and ep.steps == 12 and ep.first_success_step is None
    assert np.array(ep.actions).shape == (12, 7) and np.array(ep.eef_pos).shape == (13, 3)
    assert ep.scene_id == scene.scene_id and ep.init_eef_drift_m < 0.01
    write_episodes(tmp_path / "e.parquet", [ep])
    back = read_episodes(tmp_path / "e.parquet")[0]
    assert back.offsets == ep.offsets and back.success == ep.success  # offsets stored as float64
    np.testing.assert_allclose(back.eef_pos, ep.eef_pos, atol=1e-6)


@pytest.mark.sim
def test_a_trial_is_deterministic_given_its_identity(scene_env, scene):
    a = run_trial(scene_env, HoldPolicy(), _trial(scene, trial=1))
    run_trial(scene_env, HoldPolicy(gripper=1.0), _trial(scene, trial=4, gripper="closed"))  # dirty the env
    b = run_trial(scene_env, HoldPolicy(), _trial(scene, trial=1))
    assert a.offsets == b.offsets and a.policy_seed == b.policy_seed
    assert a.eef_pos == b.eef_pos


@pytest.mark.sim
def test_an_rd_rerun_starts_from_the_rollout_state_unperturbed(scene_env, scene, fixture_run):
    t = _trial(scene, mode="rd", rd_phase="pre", rd_start_step=20, rd_folder=fixture_run.episode, horizon=3)
    ep = run_trial(scene_env, HoldPolicy(), t)
    assert ep.mode.value == "rd" and ep.offsets == {} and ep.rd_start_step == 20
    assert "__rd__" in t.unit_id and t.unit_id.endswith("s0020")


@pytest.mark.sim
def test_an_official_trial_starts_from_libero_init_state_number_trial_unperturbed(scene_env, scene, monkeypatch):
    starts = []
    reset_to = scene_env.reset_to
    monkeypatch.setattr(scene_env, "reset_to", lambda state: (starts.append(np.array(state)), reset_to(state))[1])
    t = _trial(scene, mode="official", trial=1, horizon=3)
    ep = run_trial(scene_env, HoldPolicy(), t)
    np.testing.assert_array_equal(starts[-1], scene_env.task.init_states()[1])
    assert (ep.mode.value, ep.offsets, ep.episode_id, ep.level, ep.scene_step) == ("official", {}, "official-i01", None, 0)
    assert "__official__" in t.unit_id


@pytest.mark.sim
def test_a_state_of_the_wrong_length_is_an_episode_error_naming_the_file(scene_env, scene, tmp_path):
    bad = tmp_path / "step_0001_sim_state.npy"
    np.save(bad, np.zeros(10))
    broken = dataclasses.replace(scene, state_path=bad)
    with pytest.raises(EpisodeError, match="step_0001_sim_state.npy") as e:
        run_trial(scene_env, HoldPolicy(), _trial(broken))
    assert e.value.reason == "state_mismatch"


@pytest.mark.sim
def test_temporal_context_reaches_only_policies_that_accept_it(scene_env, scene):
    class Accepting(HoldPolicy):
        accepts_context = True
        cameras = ("agentview",)

    plain, accepting = HoldPolicy(), Accepting()
    run_trial(scene_env, plain, _trial(scene, horizon=1, temporal_context="initial_frame"))
    ep = run_trial(scene_env, accepting, _trial(scene, horizon=1, temporal_context="initial_frame"))
    assert plain.contexts == [{}]
    ctx = accepting.contexts[0]
    assert ctx["kind"] == "initial_frame" and ep.temporal_context == "initial_frame"
    assert ctx["initial_images"]["agentview"].shape == (64, 64, 3)
    np.testing.assert_array_equal(ctx["initial_state"], scene_env.task.init_states()[0])  # episode fixture-i00


def test_eval_episode_rejects_an_unknown_gripper_condition():
    with pytest.raises(ValueError):
        EvalEpisode.model_validate({"gripper": "half"})
