"""A frying pan is taken by its handle and slid into a shelf compartment (real simulator,
LIBERO kitchen scene 9): the rim grasp closed on air and lowering from above hit the board."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.recovery import make_recovery_expert
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.slide_in import compartment
from pipeline.rollout import run_episode
from pipeline.sim import build_env, tasks
from tests.policies.failure_states import start

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("pan_skills")]
PAN = "chefmate_8_frypan_1"


@pytest.fixture(scope="module")
def pan_to_shelf():
    task = tasks(["libero_90"])[40]  # put the frying pan on the cabinet shelf
    env = build_env(task)
    yield task, env
    env.close()


def test_the_pan_is_grasped_on_its_handle_across_it(pan_to_shelf):
    _, env = pan_to_shelf
    start(env)
    s = Scene(env)
    g = plan_grasp(s, PAN)
    handle = max(env.object_boxes(PAN), key=lambda b: float(np.ptp(b[:, :2], axis=0).max()))
    assert np.all(handle[0, :2] <= g.pos[:2]) and np.all(g.pos[:2] <= handle[1, :2])
    # the handle runs along y: the fingers close along x
    assert abs(abs(g.yaw) - np.pi / 2) < 0.05


def test_shelf_levels_are_compartments_open_towards_the_table_but_its_top_is_not(pan_to_shelf):
    _, env = pan_to_shelf
    s = Scene(env)
    for level in ("top_region", "bottom_region"):
        comp = compartment(s, f"wooden_two_layer_shelf_1_{level}")
        assert comp is not None and np.allclose(comp.out, [0, 1, 0])
        assert 0.05 < comp.ceiling - comp.floor < 0.15
    assert compartment(s, "wooden_two_layer_shelf_1_top_side") is None


def test_the_recovery_expert_slides_the_pan_onto_the_shelf(pan_to_shelf):
    task, env = pan_to_shelf
    start(env)
    policy = make_recovery_expert(env, task, seed=0)
    result = run_episode(env, policy, horizon=250, chunk_size=8)
    assert result.success, policy.events
