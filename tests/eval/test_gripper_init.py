from __future__ import annotations

import numpy as np
import pytest

from pipeline.eval.gripper_init import init_gripper
from pipeline.eval.scenes import find_scenes

DRIFT_TOLERANCE_M = 0.01


@pytest.fixture(scope="module")
def scene(fixture_run):
    return find_scenes(fixture_run.scenes)[0][0]


@pytest.mark.sim
@pytest.mark.parametrize("condition", ["open", "closed"])
def test_gripper_initializes_without_moving_the_arm(scene_env, scene, condition, record_property):
    env = scene_env
    env.reset_to(np.load(scene.state_path))
    start = env.eef_pose()[0]
    qpos_before = env.get_state()[1 : 1 + 7]
    g = init_gripper(env, condition, steps=20)
    drift = float(np.linalg.norm(env.eef_pose()[0] - start))
    record_property("eef_drift_m", drift)
    print(f"{condition}: eef drift {drift * 1000:.2f} mm, opening {g.opening * 1000:.1f} mm")
    assert drift == pytest.approx(g.eef_drift_m, abs=1e-12)
    assert drift < DRIFT_TOLERANCE_M
    if condition == "open":
        assert g.opening > 0.075  # fully open is ~0.08 m between the finger joints
    else:
        assert g.opening < 0.005  # nothing between the fingers in this scene: nearly shut
    # the arm joints moved by a tiny amount only (no teleporting, no swing)
    assert np.abs(env.get_state()[1 : 1 + 7] - qpos_before).max() < 0.02


@pytest.mark.sim
def test_the_controller_goal_is_re_anchored_after_initialization(scene_env, scene):
    env = scene_env
    env.reset_to(np.load(scene.state_path))
    init_gripper(env, "closed", steps=20)
    ctrl = env.env.robots[0].controller
    np.testing.assert_allclose(ctrl.goal_pos, env.eef_pose()[0], atol=1e-6)
    # a further zero action now holds the arm where it is
    here = env.eef_pose()[0]
    env.settle(5, gripper=1.0)
    assert np.linalg.norm(env.eef_pose()[0] - here) < 1e-3


def test_an_unknown_gripper_condition_is_rejected():
    with pytest.raises(ValueError, match="open"):
        init_gripper(None, "half", steps=5)


@pytest.fixture(scope="module")
def holding_state(scene_env):
    """A state where the clean scripted expert holds the target bowl lifted off the table."""
    from pipeline.config import PolicyConfig
    from pipeline.policies.factory import make_policy
    from pipeline.rollout import run_episode

    env = scene_env
    env.reset_to_init(0)
    bowl = "akita_black_bowl_1"
    rest_z: list[float] = []  # the bowl's height once the scene has settled (step 5)
    found: list[np.ndarray] = []

    def on_step(info) -> None:
        z = env.object_pose(bowl)[0][2]
        if info.step == 5:
            rest_z.append(z)
        left, right = env.finger_contacts()
        if rest_z and not found and info.action[6] > 0 and bowl in left and bowl in right and z > rest_z[0] + 0.03:
            found.append(env.get_state())

    policy = make_policy(PolicyConfig())
    policy.reset(env.task, 0)
    run_episode(env, policy, horizon=200, chunk_size=8, stop_on_success=True, on_step=on_step)
    assert found, "the scripted expert never lifted the bowl: fixture cannot be built"
    return bowl, found[0]


@pytest.mark.sim
def test_a_closed_gripper_stops_on_a_held_object_and_keeps_it(scene_env, holding_state):
    bowl, state = holding_state
    env = scene_env
    env.reset_to(state)
    lifted = env.object_pose(bowl)[0]
    g = init_gripper(env, "closed", steps=20)
    left, right = env.finger_contacts()
    print(f"holding: closed opening {g.opening * 1000:.1f} mm, eef drift {g.eef_drift_m * 1000:.2f} mm")
    # stopped on the bowl's thin rim: wider than the empty closed grip (~1.6 mm), far from open
    assert 0.003 < g.opening < 0.03
    assert bowl in left and bowl in right
    assert np.linalg.norm(env.object_pose(bowl)[0] - lifted) < 0.01  # still held where it was
    assert g.eef_drift_m < DRIFT_TOLERANCE_M


@pytest.mark.sim
def test_an_open_gripper_lets_go_of_a_held_object(scene_env, holding_state):
    bowl, state = holding_state
    env = scene_env
    env.reset_to(state)
    g = init_gripper(env, "open", steps=20)
    left, right = env.finger_contacts()
    assert g.opening > 0.075
    assert not (bowl in left and bowl in right)
    assert g.eef_drift_m < DRIFT_TOLERANCE_M
