"""The scripted expert in the real LIBERO simulator (one env, reused across tests)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import ScriptedNoise, ScriptedPolicyConfig
from pipeline.policies.base import Policy
from pipeline.policies.scripted import make_scripted_policy
from pipeline.rollout import observe, run_episode
from pipeline.sim import build_env, tasks

NOISY = ScriptedNoise(
    grasp_offset_m=0.01, approach_height_m=0.01, gripper_timing_steps=3, action_noise=0.1,
    speed_scale=0.3, place_offset_m=0.02,
)


@pytest.fixture(scope="module")
def spatial_env():
    task = tasks(["libero_spatial"])[0]
    env = build_env(task)
    yield task, env
    env.close()


def start(env, init: int = 0) -> None:
    env.reset_to_init(init)
    env.settle(10)


def record_actions(task, env, policy, seed: int, steps: int) -> list[np.ndarray]:
    start(env)
    policy.reset(task, seed)
    actions = []
    run_episode(env, policy, horizon=steps, chunk_size=8, on_step=lambda i: actions.append(i.action.copy()))
    return actions


@pytest.mark.sim
def test_clean_expert_solves_a_spatial_task_from_init_state_0(spatial_env):
    task, env = spatial_env
    policy = make_scripted_policy(ScriptedPolicyConfig())
    assert isinstance(policy, Policy) and policy.cameras == ()
    start(env)
    policy.reset(task, 0)
    result = run_episode(env, policy, horizon=520, chunk_size=8)
    assert result.success and result.steps < 300


@pytest.mark.sim
def test_same_seed_gives_identical_actions_and_other_seeds_differ(spatial_env):
    task, env = spatial_env
    policy = make_scripted_policy(ScriptedPolicyConfig(noise=NOISY))
    a = record_actions(task, env, policy, seed=3, steps=60)
    b = record_actions(task, env, policy, seed=3, steps=60)
    c = record_actions(task, env, policy, seed=4, steps=60)
    assert np.array_equal(np.array(a), np.array(b))
    assert not np.array_equal(np.array(a), np.array(c))


@pytest.mark.sim
def test_a_suites_own_noise_replaces_the_common_noise_for_that_suite_only(spatial_env):
    task, env = spatial_env
    noisy = record_actions(task, env, make_scripted_policy(ScriptedPolicyConfig(noise=NOISY)), seed=3, steps=40)
    own = ScriptedPolicyConfig(noise=ScriptedNoise(), noise_by_suite={task.suite: NOISY})
    other = ScriptedPolicyConfig(noise=NOISY, noise_by_suite={"libero_90": ScriptedNoise()})
    assert np.array_equal(np.array(record_actions(task, env, make_scripted_policy(own), seed=3, steps=40)),
                          np.array(noisy))
    assert np.array_equal(np.array(record_actions(task, env, make_scripted_policy(other), seed=3, steps=40)),
                          np.array(noisy))
    with pytest.raises(ValueError, match="unknown suite"):
        ScriptedPolicyConfig(noise_by_suite={"libero_100": NOISY})


@pytest.mark.sim
def test_chunks_are_n_by_7_within_unit_bounds(spatial_env):
    task, env = spatial_env
    policy = make_scripted_policy(ScriptedPolicyConfig(noise=NOISY, chunk_len=16))
    start(env)
    policy.reset(task, 1)
    for step in range(0, 80, 16):
        chunk = policy.act(observe(env, policy, step))
        assert chunk.ndim == 2 and chunk.shape[1] == 7 and 1 <= len(chunk) <= 16
        assert np.all(np.abs(chunk) <= 1.0)
        for a in chunk:
            env.step(a)


@pytest.mark.sim
def test_a_closed_empty_gripper_is_opened_before_anything_else(spatial_env):
    task, env = spatial_env
    start(env)
    env.settle(15, gripper=1.0)  # a restored failure scene with the hand closed on nothing
    policy = make_scripted_policy(ScriptedPolicyConfig())
    policy.reset(task, 0)
    chunk = policy.act(observe(env, policy, 0))
    assert policy.phase == "release" and np.all(chunk[:, 6] == -1.0)


@pytest.mark.sim
def test_act_without_privileged_state_names_the_problem(spatial_env):
    task, env = spatial_env
    policy = make_scripted_policy(ScriptedPolicyConfig())
    policy.reset(task, 0)
    obs = observe(env, policy, 0)
    obs.sim = None
    with pytest.raises(ValueError, match="privileged state"):
        policy.act(obs)


@pytest.mark.sim
def test_recording_the_truth_changes_no_action_even_when_the_recording_fails(spatial_env, monkeypatch):
    import json

    from pipeline.policies.scripted.truth import TruthLog

    task, env = spatial_env
    policy = make_scripted_policy(ScriptedPolicyConfig(noise=NOISY))

    def watched() -> list[np.ndarray]:
        start(env)
        policy.reset(task, 3)
        acts = []

        def hook(info):
            acts.append(info.action.copy())
            policy.on_step(info.step, info.action)

        run_episode(env, policy, horizon=60, chunk_size=8, on_step=hook)
        return acts

    plain = record_actions(task, env, policy, seed=3, steps=60)  # nobody watches the steps
    recorded = watched()
    table = policy.truth_table()
    assert table.num_rows >= 1 and table.column("skill")[0].as_py() == "pick_place"

    def boom(self):
        raise RuntimeError("sensor fault")

    monkeypatch.setattr(TruthLog, "_sample", boom)
    broken = watched()
    assert np.array_equal(np.array(plain), np.array(recorded)) and np.array_equal(np.array(plain), np.array(broken))
    meta = json.loads(policy.truth_table().schema.metadata[b"truth"])
    assert policy.truth_table().num_rows == 0 and "sensor fault" in meta["error"]
