"""The insert skill reads the microwave's door opening from the live model and puts the
mug in through it (libero_10 task 9, which the top-down expert never finished)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.policies.scripted import insert
from pipeline.policies.scripted.recovery import make_recovery_expert
from pipeline.policies.scripted.scene import Scene
from pipeline.rollout import run_episode
from pipeline.sim import build_env, tasks

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("insert")]

MUG_IN = ("in", "white_yellow_mug_1", "microwave_1_heating_region")


@pytest.fixture(scope="module")
def mug_task():
    task = tasks(["libero_10"])[9]  # put the yellow and white mug in the microwave and close it
    env = build_env(task)
    yield task, env
    env.close()


def test_the_microwave_opening_faces_the_open_door_with_floor_below_roof(mug_task):
    _, env = mug_task
    env.reset_to_init(0)
    env.settle(10)
    op = insert.opening(env, MUG_IN[2])
    assert op is not None
    np.testing.assert_allclose(op.inward, [0.0, 1.0, 0.0])  # the door opens on the robot's -y side
    assert op.front < env.region(MUG_IN[2]).pos[1] < op.back
    assert op.floor < env.region(MUG_IN[2]).pos[2] < op.ceiling
    assert op.ceiling - op.floor < 0.15  # too low for a top-down hand above a 10 cm mug
    assert insert.can_insert(Scene(env), MUG_IN)
    assert not insert.roofed(env, ("close", "microwave_1"))


def test_the_mug_goes_in_through_the_opening_and_the_door_is_closed(mug_task):
    task, env = mug_task
    env.reset_to_init(0)
    env.settle(10)
    policy = make_recovery_expert(env, task, seed=0)
    result = run_episode(env, policy, horizon=520, chunk_size=8)
    assert result.success, policy.events
