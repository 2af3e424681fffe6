from __future__ import annotations

import numpy as np
import pytest

from pipeline.eval.perturb import offset_state, sample_offsets
from pipeline.eval.protocol import Trial, run_trial
from pipeline.eval.scenes import find_scenes
from tests.eval.conftest import HoldPolicy


def test_offsets_are_reproducible_from_seed_scene_and_trial_only():
    objs = ["plate_1", "bowl_1", "cookies_1"]
    a = sample_offsets(0, "s/t/e/step_0040", 3, objs, 0.02)
    assert a == sample_offsets(0, "s/t/e/step_0040", 3, list(reversed(objs)), 0.02)
    assert a != sample_offsets(0, "s/t/e/step_0040", 4, objs, 0.02)
    assert a != sample_offsets(1, "s/t/e/step_0040", 3, objs, 0.02)
    assert a != sample_offsets(0, "s/t/e/step_0041", 3, objs, 0.02)


def test_offsets_stay_within_the_bound_over_many_draws():
    draws = np.array([v for t in range(300) for v in sample_offsets(7, "x", t, ["a", "b"], 0.02).values()])
    assert np.abs(draws).max() <= 0.02
    assert np.abs(draws).max() > 0.019  # uniform over the whole range, not a narrow band
    assert abs(draws.mean()) < 0.002


def test_offset_state_moves_only_the_named_xy_entries():
    state = np.arange(20, dtype=float)
    out = offset_state(state, {"a": 2, "b": 9}, {"a": (0.01, -0.02), "b": (0.005, 0.0)})
    changed = np.flatnonzero(out != state)
    assert changed.tolist() == [3, 4, 10]  # +1 for the time entry; b's dy is zero
    assert out[3] - state[3] == pytest.approx(0.01)
    with pytest.raises(KeyError, match="no free joint"):
        offset_state(state, {"a": 2}, {"c": (0.0, 0.0)})


@pytest.fixture(scope="module")
def scene(fixture_run):
    return find_scenes(fixture_run.scenes)[0][0]


def _trial(scene, policy: str, trial: int = 0, gripper: str = "open") -> Trial:
    return Trial(scene=scene, policy=policy, policy_kind="test", gripper=gripper, trial=trial, seed=0,
                 chunk_size=8, horizon=4, max_offset_m=0.02, gripper_settle_steps=20)


@pytest.mark.sim
def test_perturbation_moves_only_free_joint_objects_and_by_at_most_2cm(scene_env, scene):
    from pipeline.eval.perturb import perturb

    env = scene_env
    env.reset_to(np.load(scene.state_path))
    before = env.get_state()
    poses_before = env.object_poses()
    offsets = perturb(env, 0, scene.scene_id, 0, 0.02)
    after = env.get_state()

    free = env.free_joints()
    assert set(offsets) == set(free) and len(free) == 5
    assert all(abs(d) <= 0.02 for dxy in offsets.values() for d in dxy)
    nq = env.env.sim.model.nq
    expected = {1 + a + k for a in free.values() for k in (0, 1)}
    changed = set(np.flatnonzero(after != before).tolist())
    assert changed <= expected and len(changed) >= 2 * len(free) - 1
    # hinge and slide joints (drawers, the stove knob), the robot and all velocities untouched
    m = env.env.sim.model
    others = [m.joint_id2name(j) for j in range(m.njnt) if m.jnt_type[j] in (2, 3)]
    assert {"wooden_cabinet_1_top_level", "flat_stove_1_button", "robot0_joint1"} <= set(others)
    for j in range(m.njnt):
        if m.jnt_type[j] in (2, 3):
            assert after[1 + m.jnt_qposadr[j]] == before[1 + m.jnt_qposadr[j]]
    np.testing.assert_array_equal(after[1 + nq :], before[1 + nq :])
    for name, (dx, dy) in offsets.items():
        moved = env.object_pose(name)[0] - poses_before[name][0]
        np.testing.assert_allclose(moved, [dx, dy, 0.0], atol=1e-9)


@pytest.mark.sim
def test_two_policies_meet_identical_offsets_for_the_same_seed(scene_env, scene):
    a = run_trial(scene_env, HoldPolicy("a", gripper=-1.0), _trial(scene, "a", trial=2))
    b = run_trial(scene_env, HoldPolicy("b", gripper=1.0, chunk=4), _trial(scene, "b", trial=2, gripper="closed"))
    other = run_trial(scene_env, HoldPolicy("a"), _trial(scene, "a", trial=3))
    assert a.offsets == b.offsets and len(a.offsets) == 5
    assert a.policy_seed == b.policy_seed
    assert other.offsets != a.offsets
    assert all(abs(d) <= 0.02 for dxy in a.offsets.values() for d in dxy)
