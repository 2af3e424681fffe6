"""Objects LIBERO's `In` check of a drawer does not count unless they are put in lying down:
a toppled wine bottle (18 cm long) into the white cabinet's bottom drawer, turned along it;
a standing ketchup bottle (its body 7 cm over its bottom) into the top drawer, tipped flat."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import ScriptedNoise
from pipeline.policies.scripted.lay_down import too_tall
from pipeline.policies.scripted.motion import Ctx
from pipeline.policies.scripted.noise import Noise, episode_rng
from pipeline.policies.scripted.placement import place_choice, region_box, turned_foot
from pipeline.policies.scripted.recovery import make_recovery_expert
from pipeline.policies.scripted.scene import Scene
from pipeline.rollout import run_episode
from pipeline.sim import build_env, tasks
from tests.policies.failure_states import set_joint, start

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("drawer_placement")]


def ctx_for(env, task) -> Ctx:
    return Ctx(scene=Scene(env), noise=Noise(ScriptedNoise(), episode_rng(0, task.task_id)))


def test_a_lying_wine_bottle_is_turned_along_the_drawer_to_fit_in_it():
    task = tasks(["libero_90"])[26]  # put the wine bottle in the bottom drawer of the cabinet
    region = "white_cabinet_1_bottom_region"
    with build_env(task) as env:
        start(env)
        set_joint(env, "white_cabinet_1_bottom_level", -0.16)  # fully out
        ctx = ctx_for(env, task)
        xy, blocked, turn = place_choice(ctx.scene, "wine_bottle_1", region)
        # lying diagonally it fits nowhere; turned along the drawer's width it does
        assert blocked == 0 and turn != 0
        size, shift = turned_foot(ctx.scene, "wine_bottle_1", turn)
        assert size[0] > 2 * size[1]  # its length now runs along the drawer (world x)
        centre, half = region_box(env, region)
        assert np.all(np.abs(xy - centre[:2]) <= half[:2])  # the body origin LIBERO tests
        assert np.all(np.abs(xy + shift - centre[:2]) + size / 2 <= half[:2] + 0.006)  # the whole bottle


def test_a_standing_ketchup_is_tipped_flat_in_the_top_drawer():
    task = tasks(["libero_90"])[32]  # put the ketchup in the top drawer of the cabinet
    with build_env(task) as env:
        start(env)
        ctx = ctx_for(env, task)
        region = "white_cabinet_1_top_region"
        assert too_tall(ctx, "ketchup_1", region) and not too_tall(ctx, "akita_black_bowl_1", region)
        policy = make_recovery_expert(env, task, seed=0)
        result = run_episode(env, policy, horizon=300, chunk_size=8)
        assert result.success
        assert env.object_state(region).check_contain(env.object_state("ketchup_1"))
