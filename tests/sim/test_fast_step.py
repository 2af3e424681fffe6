"""The fast control step gives robosuite's states and goal flags bit for bit, in every suite."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import ScriptedNoise, ScriptedPolicyConfig
from pipeline.policies.scripted import make_scripted_policy
from pipeline.sim import SimEnv, tasks
from pipeline.sim.step_check import compare, expert_episode

SUITES = ["libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90"]
NOISY = ScriptedPolicyConfig(noise=ScriptedNoise(grasp_offset_m=0.02, approach_height_m=0.015,
                                                 gripper_timing_steps=6, action_noise=0.2, speed_scale=0.5,
                                                 place_offset_m=0.03))


@pytest.mark.sim
@pytest.mark.parametrize("suite", SUITES)
def test_fast_step_matches_robosuite_bit_for_bit(suite):
    with SimEnv(tasks([suite])[0]) as env:
        # random actions: the arm flails, hits joint limits, the table, objects
        rng = np.random.default_rng(7)
        random = compare(env, 0, rng.uniform(-1, 1, (150, 7)))
        assert random.identical, f"{suite} random actions: {random}"
        # the scripted expert with noise: grasps, lifts, places (contacts under load)
        played = expert_episode(env, make_scripted_policy(NOISY), 1, 200, seed=3)
        expert = compare(env, 1, played.actions, reference=played)
        assert expert.identical, f"{suite} scripted expert: {expert}"


@pytest.mark.sim
def test_fast_and_robosuite_steps_mix_within_an_episode_with_the_same_result():
    """The controller's cache and the gripper ramp are kept as robosuite keeps them, so
    switching steppers mid-episode, around a controller reanchor, changes nothing."""
    actions = np.random.default_rng(2).uniform(-1, 1, (40, 7))

    def play(env: SimEnv, fast) -> np.ndarray:
        env.reset_to_init(0)
        for i, a in enumerate(actions):
            env.fast_step = fast(i)
            env.step(a)
            if i == 20:
                env.reanchor_controller()
        return env.get_state()

    with SimEnv(tasks(["libero_spatial"])[0]) as env:
        reference = play(env, lambda i: False)
        mixed = play(env, lambda i: i % 3 != 0)
    assert np.array_equal(reference.view(np.int64), mixed.view(np.int64))
