"""The recovery expert finishes from hand-made failure states in the real simulator, and
stops with a reason when it cannot (a goal object off the table)."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import pytest

from pipeline.policies.base import Policy
from pipeline.policies.scripted.recovery import GiveUpReason, make_recovery_expert
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.variation import variation_levels
from pipeline.policies.scripted.scene import Scene
from pipeline.rollout import run_episode
from pipeline.sim import build_env, tasks
from tests.policies import tuning_scenes
from tests.policies.failure_states import drive, grasp_wrong, lying, set_joint, set_pose, start

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("recovery_expert")]


@pytest.fixture(scope="module")
def bowl_on_plate():
    task = tasks(["libero_goal"])[8]  # put the bowl on the plate
    env = build_env(task)
    yield task, env
    env.close()


def finish(env, task, horizon: int):
    policy = make_recovery_expert(env, task, seed=0)
    assert isinstance(policy, Policy)
    result = run_episode(env, policy, horizon=horizon, chunk_size=8)
    return result, policy


def on_plate(env, obj: str) -> bool:
    return tuple(sorted((obj, "plate_1"))) in env.contacts()


def test_a_wrongly_held_object_is_put_aside_then_the_task_is_done(bowl_on_plate):
    task, env = bowl_on_plate
    start(env)
    grasp_wrong(env, "cream_cheese_1")
    assert Scene(env).holding_any() == "cream_cheese_1"
    result, policy = finish(env, task, horizon=400)
    assert result.success and policy.give_up_reason is None
    assert not on_plate(env, "cream_cheese_1")


def test_an_obstruction_on_the_placement_path_is_moved_aside_first(bowl_on_plate):
    task, env = bowl_on_plate
    start(env)
    set_pose(env, "cream_cheese_1", env.object_pose("plate_1")[0] + [0, 0, 0.05])
    assert on_plate(env, "cream_cheese_1")
    result, policy = finish(env, task, horizon=400)
    assert result.success and not on_plate(env, "cream_cheese_1")


def test_a_grasp_whose_finger_lands_on_a_neighbour_is_passed_over_for_a_clear_one(bowl_on_plate):
    from pipeline.policies.scripted.grasps import plan_grasp
    from pipeline.policies.scripted.hand import FINGER_REACH, closing_axis

    task, env = bowl_on_plate
    start(env)
    s = Scene(env)
    g = plan_grasp(s, "akita_black_bowl_1", None, 0)
    outer = g.pos + closing_axis(g.yaw) * FINGER_REACH  # (a rim grasp: the finger outside the rim)
    if np.linalg.norm(outer[:2] - s.box("akita_black_bowl_1").centre[:2]) < 0.03:
        outer = g.pos - closing_axis(g.yaw) * FINGER_REACH
    set_pose(env, "wine_bottle_1", [outer[0], outer[1], s.table_height() + 0.01])  # upright, tall
    assert "wine_bottle_1" in checks.tip_blockers(s, "akita_black_bowl_1", g, set())
    k = checks.clear_grasp_choice(s, "akita_black_bowl_1", None, 0)
    assert checks.tip_blockers(s, "akita_black_bowl_1", plan_grasp(s, "akita_black_bowl_1", None, k), set()) == []


def test_a_goal_object_off_the_table_stops_with_object_off_table(bowl_on_plate):
    task, env = bowl_on_plate
    start(env)
    set_pose(env, "akita_black_bowl_1", [0.0, 0.8, 0.3])  # beyond the table edge: it falls
    result, policy = finish(env, task, horizon=40)
    assert not result.success
    assert policy.give_up_reason == GiveUpReason.OBJECT_OFF_TABLE
    assert policy.reason_after(result.success) == GiveUpReason.OBJECT_OFF_TABLE


def test_a_toppled_bottle_is_grasped_lying_and_placed():
    task = tasks(["libero_goal"])[2]  # put the wine bottle on top of the cabinet
    with build_env(task) as env:
        start(env)
        p = env.object_pose("wine_bottle_1")[0]
        set_pose(env, "wine_bottle_1", p + [0, 0, 0.04], lying("y"), settle=30)
        assert env.object_aabb("wine_bottle_1")[1][2] - env.object_aabb("wine_bottle_1")[0][2] < 0.08  # lying
        result, policy = finish(env, task, horizon=520)
        assert result.success


def test_a_drawer_left_half_open_is_opened_the_rest_of_the_way():
    task = tasks(["libero_goal"])[0]  # open the middle drawer of the cabinet
    with build_env(task) as env:
        start(env)
        set_joint(env, "wooden_cabinet_1_middle_level", -0.06)
        assert not env.object_state("wooden_cabinet_1_middle_region").is_open()
        result, policy = finish(env, task, horizon=300)
        assert result.success


def test_variation_is_zero_noise_at_zero_and_bounded():
    assert not any(variation_levels(0.0).model_dump().values())
    levels = variation_levels(1.0)
    assert levels.action_noise == 0 and levels.gripper_timing_steps == 0 and levels.speed_scale > 0
    with pytest.raises(ValueError, match="variation"):
        variation_levels(1.5)
    assert np.isfinite(levels.grasp_offset_m)


def test_an_arm_locked_at_its_elbow_limit_is_bent_back_and_the_task_done(bowl_on_plate):
    # a failed rollout's arm stretched far out, elbow (joint 4) at its straight limit: moving
    # the hand alone cannot pull it back (the old expert spent its 400 steps stuck there)
    task, env = bowl_on_plate
    start(env)
    for i, q in enumerate([0.22, 1.59, 0.07, -0.07, -0.01, 1.6, 0.99], start=1):
        set_joint(env, f"robot0_joint{i}", q, settle=0)
    env.settle(10)
    assert checks.elbow_locked(Scene(env))
    result, policy = finish(env, task, horizon=300)
    assert result.success


@pytest.fixture(scope="module")
def white_cabinet():
    task = tasks(["libero_10"])[3]  # put the black bowl in the bottom drawer of the cabinet and close it
    env = build_env(task)
    yield task, env
    env.close()


def test_a_bowl_fits_the_white_cabinets_bottom_drawer_only_pulled_out_to_the_end(white_cabinet):
    from pipeline.config import ScriptedNoise
    from pipeline.policies.scripted.drawer_room import cramped
    from pipeline.policies.scripted.noise import Noise, episode_rng
    from pipeline.policies.scripted.motion import Ctx
    from pipeline.policies.scripted.placement import place_room

    task, env = white_cabinet
    start(env)  # the drawer starts 14.6 cm out: open, but the bowl meets its front wall or the handles above
    ctx = Ctx(scene=Scene(env), noise=Noise(ScriptedNoise(), episode_rng(0, task.task_id)))
    region = "white_cabinet_1_bottom_region"
    assert env.object_state(region).is_open()
    assert not place_room(ctx.scene, "akita_black_bowl_1", region) and cramped(ctx, region, "akita_black_bowl_1")
    set_joint(env, "white_cabinet_1_bottom_level", -0.16)
    assert place_room(ctx.scene, "akita_black_bowl_1", region) and not cramped(ctx, region, "akita_black_bowl_1")


def test_the_white_cabinets_low_bottom_drawer_is_pushed_shut():
    task = tasks(["libero_90"])[22]  # close the bottom drawer of the cabinet (a bowl stands before it)
    with build_env(task) as env:
        start(env)
        result, policy = finish(env, task, horizon=150)
        assert result.success


def test_a_mug_lying_on_its_side_is_grasped_by_its_handle_and_placed():
    task = tasks(["libero_10"])[4]  # the white mug on the left plate, the yellow-white mug on the right one
    with build_env(task) as env:
        start(env)
        p, q = env.object_pose("porcelain_mug_1")
        # turned 90 deg about its own handle axis: on its side, the handle lying flat beside it
        set_pose(env, "porcelain_mug_1", p + [0.05, 0, 0.06], quat_mul(q, lying("x")), settle=30)
        assert checks_lying(env, "porcelain_mug_1")
        result, policy = finish(env, task, horizon=520)
        assert result.success, policy.give_up_detail


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def checks_lying(env, obj: str) -> bool:
    from pipeline.policies.scripted.recovery.lying_cup import lying_handle_grasp

    return lying_handle_grasp(Scene(env), obj) is not None


def test_a_bowl_under_the_open_top_drawer_is_got_out_and_put_in():
    task = tasks(["libero_goal"])[3]  # open the top drawer and put the bowl inside
    with build_env(task) as env:
        start(env)
        set_joint(env, "wooden_cabinet_1_top_level", -0.145)  # open (LIBERO: below -0.14)
        drawer = env.joint_part_boxes("wooden_cabinet_1_top_level")
        front = [float(drawer[:, 1, 0].max()), float(drawer[:, 1, 1].max()) - 0.02]  # under its corner
        set_pose(env, "akita_black_bowl_1", [*front, env.object_pose("akita_black_bowl_1")[0][2] + 0.01])
        assert checks.overhanging_drawer(Scene(env), "akita_black_bowl_1") is not None
        # (pushed in past 6 cm, the drawer is opened again by its handle: ~530 steps here)
        result, policy = finish(env, task, horizon=650)
        assert result.success, policy.give_up_detail


def test_only_what_stands_under_the_palms_middle_blocks_a_flat_objects_first_grasp(bowl_on_plate):
    # a tall bottle the palm's edge would brush is nudged by the descent (the plain grasp
    # succeeds); moving it first cost ~200 steps and toppled it. After a failed grasp the
    # palm's full width counts.
    from pipeline.policies.scripted.grasps import plan_grasp
    from pipeline.policies.scripted.hand import closing_axis

    task, env = bowl_on_plate
    start(env)
    s = Scene(env)
    g = plan_grasp(s, "cream_cheese_1")
    ax = closing_axis(g.yaw)
    side = np.array([-ax[1], ax[0], 0.0])
    half = float(np.max(s.box("wine_bottle_1").size[:2])) / 2
    # the bottle's near side 1 cm inside the palm's edge, 6 cm out along the closing axis
    spot = g.pos + ax * 0.06 + side * (checks.PALM_HALF_M + half - 0.01)
    set_pose(env, "wine_bottle_1", [spot[0], spot[1], env.object_pose("wine_bottle_1")[0][2] + 0.005])
    keep = {"akita_black_bowl_1", "plate_1"}
    assert "wine_bottle_1" in checks.grasp_blockers(s, "cream_cheese_1", g, keep)
    assert "wine_bottle_1" not in checks.grasp_blockers(s, "cream_cheese_1", g, keep, half_width=0.0)


def test_a_goal_object_before_a_part_open_drawer_is_set_aside_without_lifting_over_the_drawer():
    # the pudding lies just in front of a drawer 83% out (not open by LIBERO's predicate):
    # it must go aside before the drawer is pulled the rest of the way. A spot across the
    # drawer's front made the carry sweep the drawer shut (and cost ~50 steps of lifting).
    from pipeline.config import ScriptedNoise
    from pipeline.policies.scripted.noise import Noise, episode_rng
    from pipeline.policies.scripted.recovery.put_aside import HAND_REACH_M, goal_points
    from pipeline.policies.scripted.motion import Ctx
    from pipeline.policies.scripted.placement import sweep_clearance

    task = tasks(["libero_90"])[5]  # put the chocolate pudding in the top drawer of the cabinet and close it
    with build_env(task) as env:
        start(env)
        joint, obj = "wooden_cabinet_1_top_level", "chocolate_pudding_1"
        set_joint(env, joint, -0.133)
        assert not env.object_state("wooden_cabinet_1_top_region").is_open()
        s = Scene(env)
        sweep = checks.drawer_sweep(s, joint)
        fr = env.joint_frame(joint)
        out = fr.axis * np.sign(fr.range[np.argmax(np.abs(fr.range))])  # the opening direction
        k = int(np.argmax(np.abs(out[:2])))
        front = sweep[1, k] if out[k] > 0 else sweep[0, k]
        p = env.object_pose(obj)[0].copy()
        p[k] = front + out[k] * (0.034 + s.box(obj).size[k] / 2)
        p[1 - k] = 0.5 * (sweep[0, 1 - k] + sweep[1, 1 - k])
        set_pose(env, obj, p)
        assert checks.under_sweep(s, obj, sweep)
        ctx = Ctx(scene=s, noise=Noise(ScriptedNoise(), episode_rng(0, task.task_id)))
        spot = checks.free_spot(s, obj, goal_points(ctx, obj), [sweep], corridor_m=HAND_REACH_M)
        assert spot is not None
        assert sweep_clearance(s, s.box(obj).centre, spot, HAND_REACH_M, {obj}) < sweep[0, 2]


# Known gap, kept running: put-aside grasps at the usual height since the milk carton of
# libero_10 task 1 (init 1) stayed wedged between the open fingers when held near its top
# (`top_hold`, removed). Grasped at mid-height, this bottle's top meets the palm and it comes
# down lying (measured: 8.8 of 15.7 cm tall). strict: a fix makes this test fail until the
# mark is removed.
@pytest.mark.xfail(strict=True, reason="a tall put-aside object is set down lying (top_hold removed)")
def test_a_tall_obstruction_is_set_aside_standing(bowl_on_plate):
    from pipeline.config import ScriptedNoise
    from pipeline.policies.scripted.noise import Noise
    from pipeline.policies.scripted.recovery.put_aside import put_aside
    from pipeline.policies.scripted.motion import Ctx

    task, env = bowl_on_plate
    start(env)
    s = Scene(env)
    obj = "wine_bottle_1"
    start_xy, tall = env.object_pose(obj)[0][:2].copy(), s.box(obj).size[2]
    ctx = Ctx(scene=s, noise=Noise(ScriptedNoise(), np.random.default_rng(0)))
    drive(env, ctx, put_aside(ctx, obj), max_steps=200)
    env.settle(10)
    assert checks.held(s) is None
    assert np.linalg.norm(env.object_pose(obj)[0][:2] - start_xy) > 0.03
    assert s.box(obj).size[2] > 0.9 * tall  # standing


@pytest.mark.sim
def test_a_frying_pan_is_set_down_with_its_origin_on_the_cook_region():
    """A tuning run's scene (libero_90 KITCHEN_SCENE9, init state 4, default noise, step 149,
    saved in `tuning_scenes.npz`): the pan, held so that its box centre lies 9 cm from
    its body origin (in the pan), was set down with its length centred on the stove and its
    origin off the cook region, on the stove but not `On` it, until the horizon."""
    pan = []
    out = tuning_attempt("libero_90", "KITCHEN_SCENE9_turn_on_the_stove_and_put_the_frying_pan_on_it", 397857303, 149,
                         watch=lambda env, _: lambda info: pan.append(env.object_pose("chefmate_8_frypan_1")[0]))
    assert out.success, (out, pan[-1:])


@pytest.mark.sim
def test_a_drawer_low_over_the_table_is_hooked_open_from_above():
    """libero_90 KITCHEN_SCENE1's bottom drawer (init state 0, zero noise): its handle bar
    is 4.6 cm over the table, too low for the tilted grip (the hand's housing meets the
    table), and the recovery expert timed out; a pitched fist hooks the bar from behind."""
    from pipeline.release.experts import attempt, recovery_expert

    task = tasks(["libero_90"])[6]  # open the bottom drawer of the cabinet
    env = build_env(task)
    try:
        out = attempt(env, task.init_states()[0], recovery_expert(env, 0, 0.0), 0, 520, 8)
    finally:
        env.close()
    assert out.success and out.steps < 250, out


def tuning_attempt(suite: str, task: str, seed: int, step: int, horizon: int = 520, init: int = 4, watch=None):
    """Run the zero-noise recovery expert with `horizon` (the release's by default) from a
    tuning run's failure scene (tune26: init state 4, default noise; other tuning runs: `init`
    0-4) at `step`, saved in `tuning_scenes.npz`; its `Outcome`. `watch(env, policy)`, if
    given, returns the attempt's per-step callback."""
    from pipeline.release.experts import attempt, recovery_expert
    from pipeline.sim import get_task

    scene = tuning_scenes.load(suite, task, init, seed, step)
    with build_env(get_task(suite, task)) as env:
        policy = recovery_expert(env, 0, 0.0)
        return attempt(env, scene, policy, 0, horizon, 8, on_step=None if watch is None else watch(env, policy))


@contextmanager
def tuning_scene(suite: str, task: str, init: int, seed: int, step: int):
    """The `Scene` of a tuning run's failure scene saved in `tuning_scenes.npz`, restored."""
    from pipeline.release.experts import restore_scene
    from pipeline.sim import get_task

    with build_env(get_task(suite, task)) as env:
        restore_scene(env, tuning_scenes.load(suite, task, init, seed, step))
        yield Scene(env)


@pytest.mark.sim
def test_a_bowl_under_the_open_drawer_goes_in_before_the_horizon():
    """libero_goal "open the top drawer and put the bowl inside", step 327: the bowl stands
    under the drawer's front. Pushed in, set aside 0.33 m off (the near spots beyond the
    sweep were blocked toward the robot) and pulled out by its handle at the plain
    expert's pace, it went in at step 549 (timeout); set aside across the far side, just
    beyond the sweep, and the handle reached and pulled faster, at step 503."""
    out = tuning_attempt("libero_goal", "open_the_top_drawer_and_put_the_bowl_inside", 506136647, 327)
    assert out.success and out.steps <= 510, out


@pytest.mark.sim
def test_a_far_bowl_is_grasped_from_a_higher_hover():
    """libero_spatial "pick up the black bowl on the cookie box ...", step 155: the bowl 0.70
    m from the robot base. Hovering 8 cm over its rim the arm locked straight and the hand
    never turned down (80 steps), the grasp missed twice and the horizon ran out; from 14
    cm over it the first grasp holds."""
    out = tuning_attempt("libero_spatial", "pick_up_the_black_bowl_on_the_cookie_box_and_place_it_on_the_plate",
                         1087795790, 155)
    assert out.success and out.steps <= 300, out


@pytest.mark.sim
@pytest.mark.parametrize("suite, index, init", [
    # the second moka pot's grasp is 0.70 m out but no rim grasp: hovered over from the far
    # bowl's 14 cm it was set down off the stove, then missed (timeout)
    ("libero_10", 8, 2),
    # the bowl beside the cabinet: its rim grasp's palm box looked 1 cm into the cabinet, and
    # the grasp chosen instead dropped it twice (timeout)
    ("libero_90", 1, 0),
    # the milk carton, knocked over by a missed grasp, turned to fit the basket: turned onto
    # the wrist's limit it stalled on the way and came down short of the basket (timeout)
    ("libero_object", 7, 0),
    # both moka pots: the second, lowered beside the first and held off its spot by it, was
    # moved over before letting go and toppled (timeout)
    ("libero_10", 8, 0),
])
def test_zero_noise_episodes_a_grasp_change_once_broke(suite, index, init):
    """From official init states at zero noise, as scripted_success.py measures them: only a
    far rim grasp hovers higher, a rim grasp's first attempt trusts the fingertip rays, a
    container's turn keeps the wrist in range, and only a placement onto an object is
    measured and moved over before the fingers open."""
    task = tasks([suite])[index]
    env = build_env(task)
    try:
        env.reset_to_init(init)
        env.settle(10)
        result, policy = finish(env, task, 520)
    finally:
        env.close()
    assert result.success and result.steps <= 460, (result.steps, policy.give_up_reason)


@pytest.mark.sim
def test_an_object_lying_against_a_basket_wall_is_pushed_clear_then_grasped():
    """A tuning run's scene (libero_object, init state 4, default noise, step 296): the
    pudding lies 1.6 cm before the basket's front wall, so every grasp candidate puts a
    finger and the palm onto the wall; every descent stopped there until the horizon. It is
    pushed along the wall, clear of it, then grasped (~200 steps)."""
    out = tuning_attempt("libero_object", "pick_up_the_chocolate_pudding_and_place_it_in_the_basket", 19454025, 296)
    assert out.success and out.steps <= 300, out


@pytest.mark.sim
def test_a_bottle_lying_beside_the_wine_rack_is_grasped_clear_of_it_and_laid_in_its_top_slot():
    """A tuning run's scene (libero_goal, init state 4, default noise, step 73): the toppled
    bottle lies beside the rack. The fingertip rays saw its grasp clear, but the palm came
    down on the rack's slats (the grasp is slid along the bottle, clear of them), and the
    bottle, set down in the tilted slot's level box, landed on the slot's lip and rolled off
    (it is aimed out along the slot's plate, behind the lip). Both: a timeout before."""
    out = tuning_attempt("libero_goal", "put_the_wine_bottle_on_the_rack", 875160940, 73)
    assert out.success and out.steps <= 380, out


@pytest.mark.sim
def test_a_wrist_pinned_at_its_limit_is_unwound_before_the_grasp():
    """libero_object, alphabet soup into the basket, step 186: the failing rollout flipped
    joint 5 by 2.6 rad and left joint 6 at 3.75 of 3.75 rad; no hand motion levels the hand
    from there (10 deg tilted, every grasp missed until the horizon). Unwound along the
    joint path to the home joints, the task is done in ~210 steps."""
    out = tuning_attempt("libero_object", "pick_up_the_alphabet_soup_and_place_it_in_the_basket",
                         2015380134, 186, horizon=320)
    assert out.success, out


@pytest.mark.sim
def test_a_drawer_pushed_shut_by_the_back_out_is_opened_again_without_setting_the_bowl_aside():
    """libero_90 KITCHEN_SCENE5, the bowl into the top drawer, step 116: pulling the
    stretched arm in pushed the open drawer half shut, and the round went on to put the bowl
    into it (it fell off the front). The round now ends when a back-out moved a part; and
    the bowl, 3 cm before the opened drawer's front and 10 cm under its floor, is not set
    aside before the drawer is opened again (~350 steps)."""
    out = tuning_attempt("libero_90", "KITCHEN_SCENE5_put_the_black_bowl_in_the_top_drawer_of_the_cabinet",
                         993743582, 116, horizon=420)
    assert out.success, out


@pytest.mark.sim
def test_a_tuning_runs_low_drawer_left_shut_is_hooked_open():
    """A tuning run's scene (libero_90 KITCHEN_SCENE1, init state 4, default noise, step 247,
    saved in `tuning_scenes.npz`): the generator's tilted grip left the bottom drawer
    shut, and the recovery expert, trying the same grip, timed out."""
    out = tuning_attempt("libero_90", "KITCHEN_SCENE1_open_the_bottom_drawer_of_the_cabinet", 1175888538, 247)
    assert out.success and out.steps < 260, out


@pytest.mark.sim
def test_a_book_lying_tilted_on_its_face_is_stood_up_in_the_hand():
    """tune26, libero_90 STUDY_SCENE2, the book into the caddy's front compartment, step
    140: the book lies across a compartment, its faces 42 deg from level. Taken for lying on
    its face, it got top-down grasps, which slid off it four times (`retries_exhausted`);
    a face steeper than 26 deg from level now leans, and the tilted grasp stands it up in
    the hand (certified in ~240 steps)."""
    out = tuning_attempt("libero_90", "STUDY_SCENE2_pick_up_the_book_and_place_it_in_the_front_compartment_of_the_caddy",
                         1975092931, 140)
    assert out.success and out.steps <= 300, out


@pytest.mark.sim
def test_a_book_stood_up_a_few_degrees_off_upright_is_still_slotted():
    """A tuning run's scene (libero_90 STUDY_SCENE2, init state 3, default noise, step 297):
    the book leans 54 deg in the right compartment. Stood up in the hand, it hung a few
    degrees off upright, its footprint over what the slot skill fits, so it was put down
    beside the slot, jammed on a wall, until the horizon. Fitted by its own size it is slotted
    and straightens as it meets the floor."""
    out = tuning_attempt("libero_90", "STUDY_SCENE2_pick_up_the_book_and_place_it_in_the_right_compartment_of_the_caddy",
                         1383291930, 297, init=3)
    assert out.success and out.steps <= 250, out


@pytest.mark.sim
def test_a_bowl_with_no_free_spot_in_front_of_the_robot_is_set_aside_further_out():
    """A tuning run's scene (libero_10 KITCHEN_SCENE4, init state 3, default noise, step 55):
    the bowl stands where the bottom drawer opens; with the drawer's sweep and the counter's
    clutter no spot in front of the robot was free, and the expert gave up holding the bowl
    (`no_plan`). A wider ring of spots takes it; the whole task then needs ~610 steps, over
    the release's 520 (still a timeout there: said in the README)."""
    out = tuning_attempt("libero_10", "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
                         1471476559, 55, horizon=660, init=3)
    assert out.success, out


@pytest.mark.sim
def test_a_mug_carried_by_its_handle_across_the_microwave_stays_aimed_at_the_opening():
    """tune26, libero_10 KITCHEN_SCENE6, the mug into the microwave, step 117 (a missed
    grasp): carried by its handle across the opening at full command, the mug turned 3.5 cm
    about the handle, met the microwave's front and fell before it (timeout). Carried across
    at half command it keeps its hold, goes in, and the door is shut within the horizon."""
    out = tuning_attempt("libero_10", "KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it",
                         1237910369, 117)
    assert out.success and out.steps <= 520, out


@pytest.mark.sim
def test_a_drawer_left_open_above_the_one_to_open_is_shut_first():
    """A tuning run's scene (tunetime: libero_90 KITCHEN_SCENE1, init state 3, step 247):
    the generator left the middle drawer fully open; its front hangs over the bottom
    drawer's handle, so the hook from above pulled on nothing until the horizon. Pushed shut
    first, the bottom drawer opens in under 300 steps."""
    out = tuning_attempt("libero_90", "KITCHEN_SCENE1_open_the_bottom_drawer_of_the_cabinet", 846456545, 247,
                         init=3)
    assert out.success and out.steps <= 300, out


@pytest.mark.sim
def test_a_fist_that_would_wind_the_wrist_onto_its_limit_pushes_turned_by_half_a_turn():
    """A tuning run's scene (tunetime: libero_10 KITCHEN_SCENE4, the bowl into the bottom
    drawer and close it, init state 2, step 112): with the bowl in, the fist turned to its
    fixed yaw wound the wrist's last joint from 2.6 onto its 2.9 rad limit, and the arm
    flailed until the horizon. A fist pushes alike turned by pi: turned the other way round
    it shuts the drawer at step ~410."""
    out = tuning_attempt("libero_10", "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
                         656804229, 112, init=2)
    assert out.success and out.steps <= 450, out


@pytest.mark.sim
@pytest.mark.parametrize("scene, seed, step, init, steps", [
    ("STUDY_SCENE2", 1169323443, 198, 0, 250),
    ("STUDY_SCENE3", 349502892, 258, 1, 510),
])
def test_a_book_leaning_toward_the_robot_is_turned_upright_in_its_plane_first(scene, seed, step, init, steps):
    """Two tuning scenes (tunebooks: libero_90 STUDY_SCENE2 and STUDY_SCENE3, the book into
    the right compartment): the book leans 43-46 deg on the caddy, its faces standing, its
    top toward the robot's base. The hand along its axis folded the elbow onto its limit 9 cm
    short of the top edge, twice, until the horizon. Grasped with the hand pointing down and
    turned in its own plane, on while it lags short of upright in the fingers, it stands
    (STUDY_SCENE2: set down in the compartment itself, done at step ~165; STUDY_SCENE3:
    turned twice, then slotted at step ~495)."""
    out = tuning_attempt("libero_90", f"{scene}_pick_up_the_book_and_place_it_in_the_right_compartment_of_the_caddy",
                         seed, step, init=init)
    assert out.success and out.steps <= steps, out


@pytest.mark.sim
@pytest.mark.parametrize("suite, task, seed, step, init, steps", [
    # the ketchup lying 15.2 cm long over a 12.3 cm basket region: laid along the diagonal
    ("libero_90", "LIVING_ROOM_SCENE1_pick_up_the_ketchup_and_put_it_in_the_basket", 979863995, 87, 4, 200),
    # the fist dragging the top drawer further out, turned the way that leaves the wrist room
    ("libero_90", "KITCHEN_SCENE1_open_the_top_drawer_of_the_cabinet_and_put_the_bowl_in_it", 1026427236, 329, 0, 470),
    # the white mug held by its rim, set down 3-4 cm off the plate's middle: moved over first
    ("libero_90", "LIVING_ROOM_SCENE5_put_the_white_mug_on_the_left_plate", 300379228, 133, 1, 150),
])
def test_version_10_certifies_three_tuning_scenes_version_9_did_not(suite, task, seed, step, init, steps):
    """Three tuning scenes version 9 left uncertified (tunetime, tunemix, tunemug). The ketchup,
    carried as it lay, came down across the basket's rims with its body 2 cm above the region,
    three times; turned to the diagonal it goes in (step ~128). The fist that drags a cramped
    drawer out wound the wrist's last joint onto its limit at a fixed yaw and crawled 165 steps
    to the drawer; turned by half a turn it gets there in ~40 and the bowl is in at step ~415.
    The white mug, held by its rim, hangs tilted and straightens as it is pressed down: it
    landed 3.0-3.7 cm off the plate's middle four times (LIBERO's `On` wants 3 cm); measured
    once lowered and moved over before the fingers open, it is on the plate at step ~90."""
    out = tuning_attempt(suite, task, seed, step, init=init)
    assert out.success and out.steps <= steps, out


@pytest.mark.sim
@pytest.mark.parametrize("suite, task, seed, step, init, steps", [
    # a lying bottle's middle too near the shoulder: grasped 4.5 cm along it, further out
    ("libero_90", "LIVING_ROOM_SCENE4_pick_up_the_salad_dressing_and_put_it_in_the_tray", 1524038178, 103, 4, 360),
    # the mug carried by its handle across to the microwave's front, the gentle leg ended sooner
    ("libero_10", "KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it", 487775941, 119, 3, 515),
])
def test_version_11_certifies_two_tuning_scenes_version_10_did_not(suite, task, seed, step, init, steps):
    """Two tuning scenes version 10 left uncertified (tune26, tunemug; both timeouts). The salad
    dressing lies beside the robot in LIVING_ROOM_SCENE4, whose base stands nearer the objects
    than the kitchens': the grasp at its middle, 0.37 m from the shoulder, folded the elbow onto
    its limit 4.5 cm short, twice (missed grasp, then the horizon); slid along the bottle to
    0.39 m it is picked up at once (in the tray at step ~320). The mug's gentle leg across to the
    microwave stalled 3.3-3.5 cm short of its end, over the 3 cm it stopped at, and waited out
    its 120 steps; ending 4.5 cm short, the door is shut at step ~505 (541 before)."""
    out = tuning_attempt(suite, task, seed, step, init=init)
    assert out.success and out.steps <= steps, out


@pytest.mark.sim
def test_an_upside_down_book_is_turned_with_the_hand_pointing_away_from_the_base():
    """A tuning scene (tunebooks: libero_90 STUDY_SCENE3, the book into the left compartment,
    init state 2, step 282): the book stands upside down on the table. Either way of turning
    it by a quarter gets it as near standing; the hand pitched back toward the base ran joint 7
    onto its limit, never reached the corner and drifted off (version 16). `_turn_way` pitches
    it away from the base, which a quarter turn still does where the book cannot be tipped
    over (version 24: `tip_book`, which takes this scene: tipped by step ~60, and the tip
    not counted as a try, so the face skill's first pinch is its best corner; counted, the
    second corner's pinch met the caddy's wall and the attempt ran out of time)."""
    from pipeline.policies.scripted.recovery.stand_book import PITCH, _turn_way, book_axes

    task = "STUDY_SCENE3_pick_up_the_book_and_place_it_in_the_left_compartment_of_the_caddy"
    with tuning_scene("libero_90", task, 2, 460143849, 282) as s:
        ax = book_axes(s, "black_book_1")
        assert ax.up[2] < -0.9  # upside down
        a1, _ = _turn_way(s, ax, 2 * PITCH, PITCH)
        away = (ax.top_mid - s.env.robot_base())[:2]
        assert float(a1[:2] @ away) > 0.0, a1  # the grasping hand pitched away from the base
    seen = {}

    def watch(env, _):
        def on_step(info):
            if info.step in (0, 100):
                seen[info.step] = book_axes(Scene(env), "black_book_1").up
        return on_step

    out = tuning_attempt("libero_90", task, 460143849, 282, init=2, watch=watch)
    assert abs(float(seen[100][2])) < 0.5, seen  # tipped: no longer upside down
    assert out.success, out


@pytest.mark.sim
@pytest.mark.parametrize("task, seed, step, init, steps", [
    ("LIVING_ROOM_SCENE3_pick_up_the_ketchup_and_put_it_in_the_tray", 249102819, 87, 4, 200),
    ("LIVING_ROOM_SCENE4_pick_up_the_salad_dressing_and_put_it_in_the_tray", 41879565, 204, 2, 260),
])
def test_a_bottle_lying_beside_the_base_is_grasped_with_the_hand_pitched_toward_it(task, seed, step, init, steps):
    """Two tuning scenes (tunel3, version 11 timeouts): a bottle lies pointing at the robot's
    base, so near that even its far end folds the elbow onto its limit with the hand pointing
    down: the transport and the hover stalled 80 steps each, 3-6 cm short, and two grasps
    missed. Pitched 35 deg about the fingers' closing axis toward the base (fingertips in,
    wrist out), the hand reaches it at once, and the bottle goes into the tray as held (done
    at step ~150 and ~220)."""
    out = tuning_attempt("libero_90", task, seed, step, init=init)
    assert out.success and out.steps <= steps, out


@pytest.mark.sim
def test_a_bowl_perched_on_the_bottom_drawers_wall_ends_in_the_closed_drawer():
    """The outcome the test below does not assert: the same scene closed at step ~290 where
    it was first found (remade leaning there); on later machines the level perched bowl, put
    in straight from the wall, came down leaning on the side wall and the attempt timed out
    (a strict known failure, versions 19-31). Since version 32 the leaning bowl is pressed
    flat (`press_flat`) and the drawer closes."""
    out = tuning_attempt("libero_10", "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
                         173332742, 159, init=3)
    assert out.success and out.steps <= 330, out


@pytest.mark.sim
def test_a_bowl_perched_on_the_bottom_drawers_wall_is_put_in_again_before_the_first_push():
    """A tuning scene (tunewide: libero_10 KITCHEN_SCENE4, init state 3, step 159): the bowl
    dropped into the open bottom drawer sits on its wall, 6.5 cm over the floor, its top over
    the drawer's walls. Version 12 pushed the drawer at once, tipping the bowl over; now the
    perched bowl is taken out before any push and put in again, down on the floor
    (`rules.proud_in_drawer`, `checks.perched_in_drawer`).

    Whether the task is then done depends on the CPU: on the machine this case was found on,
    the bowl was remade leaning (set aside, put in from the table: closed at step ~290); on
    the machines of the twelfth and thirteenth sessions and CI's (AMD EPYC) the same seed
    remakes it level, it is put in straight from the wall, comes down leaning on the side
    wall, and the attempt times out. The rule is asserted here; the outcome is the strict
    known failure above."""
    from pipeline.policies.scripted.recovery import checks
    from pipeline.policies.scripted.scene import Scene

    joint, bowl = "white_cabinet_1_bottom_level", "akita_black_bowl_1"
    seen = []  # (phase, bowl perched, bowl's bottom over the drawer's walls)

    def watch(env, policy):
        def on_step(_):
            s = Scene(env)
            top = float(env.joint_part_boxes(joint)[:, 1, 2].max())
            seen.append((policy.phase, checks.perched_in_drawer(s, joint, bowl), s.box(bowl).lo[2] > top))
        return on_step

    tuning_attempt("libero_10", "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it",
                   173332742, 159, init=3, watch=watch)
    assert seen and seen[0][1], seen[:1]  # the remade scene: perched
    first_push = next(i for i, (phase, _, _) in enumerate(seen) if phase == "face_drawer")
    assert any(out for _, _, out in seen[:first_push]), "the bowl was not taken out before the push"
    assert not seen[first_push][1], "the bowl is still perched when the drawer is pushed"


@pytest.mark.sim
def test_the_fist_that_pushes_a_door_shut_closes_on_the_way_there():
    """The microwave's door (libero_10 KITCHEN_SCENE6, init state 0: the door open, the hand
    open) pushed shut by a fist (`articulated.close_part`, both experts): the hand sets off at
    once and the fingers shut while it travels, not standing still first (14 steps of the
    microwave mug's margin to the horizon), and they are shut before the fist meets the door."""
    from pipeline.config import ScriptedNoise
    from pipeline.policies.scripted import articulated
    from pipeline.policies.scripted.motion import Ctx
    from pipeline.policies.scripted.noise import Noise

    task = tasks(["libero_10"])[9]  # put the yellow and white mug in the microwave and close it
    with build_env(task) as env:
        start(env)
        ctx = Ctx(scene=Scene(env), noise=Noise(ScriptedNoise(), np.random.default_rng(0)))
        assert not articulated.is_closed_enough(env, "microwave_1")
        seen = []

        def watched(plan):
            for prim in plan:
                seen.append((prim.label, ctx.scene.gripper_open()))
                yield prim

        drive(env, ctx, watched(articulated.close_part(ctx, ("close", "microwave_1"))), max_steps=200)
        assert articulated.is_closed_enough(env, "microwave_1")
        assert seen[0][0] != "make_fist" and "make_fist" not in dict(seen), seen
        assert dict(seen)["face_door"] is False, seen  # the fingers already shut there


@pytest.mark.sim
@pytest.mark.parametrize("suite, task, seed, step, init, steps", [
    # the bowl to stack onto, tipped onto its neighbour: leaning 40 degrees
    ("libero_90", "KITCHEN_SCENE2_stack_the_middle_black_bowl_on_the_back_black_bowl", 1571136195, 111, 4, 230),
    # the red mug knocked onto the white mug: leaning 57 degrees on it
    ("libero_90", "LIVING_ROOM_SCENE5_put_the_red_mug_on_the_right_plate", 1863214217, 110, 3, 360),
])
def test_version_13_grasps_a_leaning_object_where_its_wall_stands_vertical(suite, task, seed, step, init, steps):
    """Two tuning scenes version 12 left uncertified (tunewide, tunetime; both
    `retries_exhausted` after four tries): an object leaning on a neighbour, grasped by its
    rim under the box top, which over a tilted rim is air on the low side and the wall's
    upward-facing outside on the high side. By the rim a quarter turn round from its highest
    point, where the wall stands vertical (`grasps.side_rim`), the task is done at steps
    ~180 and ~300."""
    out = tuning_attempt(suite, task, seed, step, init=init)
    assert out.success and out.steps <= steps, out


@pytest.mark.sim
def test_version_16_drags_the_drawer_pushed_back_out_with_the_fist_and_opens_the_hand_on_the_way():
    """tunewide, libero_goal "open the top drawer and put the bowl inside", step 369: the
    bowl under the open drawer's front. The drawer pushed back to 4.3 cm out was pulled out
    again by its handle (tilt, reach, pull, untilt): the bowl went in at step 545 (version
    14, a timeout). Dragged out by the fist (step 528), whose fingers then open on the way
    to the bowl instead of opening and backing off first (`checks.opens_on_the_way`): step
    ~516, inside the release's horizon (520)."""
    out = tuning_attempt("libero_goal", "open_the_top_drawer_and_put_the_bowl_inside", 52122322, 369)
    assert out.success, out


@pytest.mark.sim
def test_a_book_lying_on_its_face_is_pinched_by_a_top_corner_and_stood_up():
    """A tuning-state scene (`benchmarks/book_poses.py`, kind `face`: libero_90 STUDY_SCENE2,
    the book into the back compartment, init state 1, seed 7021): the goal book lies flat on a
    face, which no top-down grasp takes (version 18: every such scene `retries_exhausted` or a
    timeout). Pinched across a top corner's two edge faces, lifted level, the hand turned by
    the book's whole tilt high over the table, it is set down standing on its bottom edge, then
    grasped from above and slotted as usual."""
    from benchmarks.book_poses import make_scene
    from pipeline.policies.scripted.recovery.face_book import lying_on_face
    from pipeline.release.experts import attempt, recovery_expert
    from pipeline.sim import get_task

    env = build_env(get_task("libero_90", "STUDY_SCENE2_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy"))
    try:
        env.reset_to_init(1)
        state, book = make_scene(env, "face", np.random.default_rng(7021))
        assert lying_on_face(Scene(env), book) is not None
        seen = {}

        def standing(info):
            ax = lying_on_face(Scene(env), book)
            if ax is None and "stood" not in seen and not Scene(env).holding(book):
                seen["stood"] = info.step

        out = attempt(env, state, recovery_expert(env, 0, 0.0), 0, 520, 8, on_step=standing)
        assert out.success, out
        assert "stood" in seen, seen  # off its face and let go before it was carried in
    finally:
        env.close()


@pytest.mark.sim
@pytest.mark.parametrize("task, seed, step, init", [
    # the descents to the bottle stood still 3.5 and 2.7 cm over the grasp, 51 steps each
    ("LIVING_ROOM_SCENE3_pick_up_the_tomato_sauce_and_put_it_in_the_tray", 1449910339, 101, 3),
    # the book's grasps: four descents ended standing still, 51-56 steps each
    ("STUDY_SCENE3_pick_up_the_book_and_place_it_in_the_front_compartment_of_the_caddy", 70441778, 220, 0),
])
def test_version_21_ends_an_empty_hands_move_that_stands_still(task, seed, step, init):
    """Two tuning scenes version 20 left uncertified (tunewide, tunebooks; timeout and
    `retries_exhausted` at the release's horizon): the empty hand's moves stood still against
    something until their max_steps. Ended after 16 steps without 5 mm or 0.03 rad of
    progress (`expert.STALL_*`), the same tries fit in the horizon: both certified."""
    from pipeline.policies.scripted.primitives import Move

    ran = {}  # id -> (primitive, steps it was running); the primitive kept, so ids stay unique

    def watch(env, policy):
        def on_step(_):
            prim = policy._prim
            ran[id(prim)] = (prim, ran.get(id(prim), (prim, 0))[1] + 1)
        return on_step

    out = tuning_attempt("libero_90", task, seed, step, init=init, watch=watch)
    ended = [p.label for p, n in ran.values() if isinstance(p, Move) and p.steps >= p.max_steps and n < p.max_steps - 8]
    assert out.success, out
    assert ended, "no move was ended for standing still"


def _book_tilt(env, book: str) -> float:
    from pipeline.policies.scripted.recovery.stand_book import _off_upright

    return float(np.degrees(_off_upright(Scene(env), book)))


@pytest.mark.sim
def test_version_22_turns_a_face_down_book_high_enough_that_it_stands_when_let_go():
    """tunebooks, libero_90 STUDY_SCENE1 (front compartment), init 1, step 101: the book lies on
    its face, pinched by a top corner and turned. At the lift's height the hand pointing level
    sagged back from 88 to 76 deg (joint 6 on its limit), the book was let go 14-23 deg short
    of standing and fell back on its face, twice: a timeout (version 21). Turned 8 cm higher
    (`face_book.TURN_RISE_M`), it stands when first let go, and the task is done."""
    tilt_at_retreat = []

    def watch(env, policy):
        def on_step(_):
            if getattr(policy._prim, "label", "") == "retreat" and not tilt_at_retreat:
                tilt_at_retreat.append(_book_tilt(env, "black_book_1"))
        return on_step

    out = tuning_attempt("libero_90", "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_front_compartment_of_the_caddy",
                         1194760578, 101, init=1, watch=watch)
    assert tilt_at_retreat and tilt_at_retreat[0] < 8.0, tilt_at_retreat  # standing after the first turn
    assert out.success, out


@pytest.mark.sim
def test_version_22_unwinds_the_arm_after_standing_a_face_down_book():
    """tunebooks, libero_90 STUDY_SCENE3 (front compartment), init 1, step 192: the book, lying on
    its face 0.6 m out, stood by step 165; levelling the hand there and backing out in the hand's
    space locked the elbow straight, and every grasp of the standing book after hovered off it
    (version 21: a timeout). Taken to the home joints along a joint-space path (`unwind`), the
    arm grasps it with the elbow bent and the book goes in."""
    locked = []

    def watch(env, policy):
        def on_step(info):
            label = getattr(policy._prim, "label", "")
            if label in ("hover", "descend") and info.step > 200 and checks.elbow_locked(Scene(env)):
                locked.append((info.step, label))
        return on_step

    out = tuning_attempt("libero_90", "STUDY_SCENE3_pick_up_the_book_and_place_it_in_the_front_compartment_of_the_caddy",
                         277128261, 192, init=1, watch=watch)
    assert not locked, locked[:5]
    assert out.success, out


def _watch_held(held: list[str]):
    """A `tuning_attempt` watch that appends each object the hand starts to hold, in order."""
    def watch(env, _):
        def on_step(_):
            h = Scene(env).holding_any()
            if h is not None and (not held or held[-1] != h):
                held.append(h)
        return on_step
    return watch


@pytest.mark.sim
def test_version_22_sets_aside_what_takes_a_fingertips_spot_at_a_face_down_books_corners():
    """tunebooks, libero_90 STUDY_SCENE1 (left compartment), init 2, step 63: the book lies on its
    face between the caddy and a mug, whose boxes take a fingertip's spot at each top corner.
    With no corner to pinch, the attempts fell to top-down grasps of the flat book, which slid
    off it twice before the mug was set aside (version 21: a timeout). The mug, the only
    movable blocker, is now set aside first (`face_book.pinch_blockers`), then the book pinched."""
    from pipeline.policies.scripted.recovery.face_book import lying_on_face, pinch_blockers

    task = "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_left_compartment_of_the_caddy"
    with tuning_scene("libero_90", task, 2, 92547534, 63) as s:
        face = lying_on_face(s, "black_book_1")
        assert face is not None
        assert pinch_blockers(s, "black_book_1", face, {"black_book_1", "desk_caddy_1"}) == ["white_yellow_mug_1"]
    held = []
    watch = _watch_held(held)

    out = tuning_attempt("libero_90", task, 92547534, 63, init=2, watch=watch)
    assert held[:1] == ["white_yellow_mug_1"], held  # the mug first, no grasp of the flat book before
    assert out.success, out


@pytest.mark.sim
def test_version_23_sets_aside_what_the_tilted_hand_meets_at_a_books_edge():
    """tunebooks, libero_90 STUDY_SCENE1 (right compartment), init 0, step 187: the book lies on
    its long side, its top edge against a mug. Turned by a quarter, it is held by a top corner
    with the hand pitched 45 deg over the mug: the hand met the mug, the edge move stalled 80
    steps and the grasp missed; the second turn stood the book, too late (version 22: a
    timeout). The mug, in the tilted hand's way (`stand_book.edge_blockers`), is now set aside
    first. The same check finds the mug a book leans on in tune26's STUDY_SCENE3 (front
    compartment, init 4, step 100), whose hand knocked it flat (version 22: a timeout)."""
    from pipeline.policies.scripted.recovery.stand_book import edge_blockers, stand_tilt

    leaning = "STUDY_SCENE3_pick_up_the_book_and_place_it_in_the_front_compartment_of_the_caddy"
    with tuning_scene("libero_90", leaning, 4, 72376665, 100) as s:
        book = stand_tilt(s, "black_book_1")
        assert book is not None
        assert edge_blockers(s, "black_book_1", book, {"black_book_1"}) == ["porcelain_mug_1"]
    held = []
    watch = _watch_held(held)

    task = "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_right_compartment_of_the_caddy"
    out = tuning_attempt("libero_90", task, 1296278284, 187, init=0, watch=watch)
    assert held[:1] == ["white_yellow_mug_1"], held  # the mug first, before any grasp of the book
    assert out.success, out


@pytest.mark.sim
def test_version_24_tips_an_upside_down_book_onto_a_face_before_standing_it():
    """A tuning-state scene (`benchmarks/book_poses.py`, kind `upside`: libero_90 STUDY_SCENE1,
    the book into the left compartment, init state 0, seed 11010): the goal book stands on its
    top edge. Turned by two quarters, each held by a corner with the hand pitched 45 deg, it
    ran out of time (version 23: a timeout, as 9 of that benchmark's 12 upside-down books).
    Pushed over onto a face first (`tip_book`: the closed fingers beside its upper part, on
    the side where it does not fall onto anything), it is stood up in one turn from there
    (`face_book`), grasped and slotted."""
    from benchmarks.book_poses import make_scene
    from pipeline.policies.scripted.recovery.face_book import lying_on_face
    from pipeline.policies.scripted.recovery.tip_book import tip_way, upside_down
    from pipeline.release.experts import attempt, recovery_expert
    from pipeline.sim import get_task

    env = build_env(get_task("libero_90", "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_left_compartment_of_the_caddy"))
    try:
        env.reset_to_init(0)
        state, book = make_scene(env, "upside", np.random.default_rng(11010))
        assert upside_down(Scene(env), book) is not None and tip_way(Scene(env), book) is not None
        policy = recovery_expert(env, 0, 0.0)
        seen = []  # labels in order, and whether the book lay on its face after the tip

        def watch(info):
            label = getattr(policy._prim, "label", "")
            if not seen or seen[-1] != label:
                seen.append(label)
            if label == "rise" and "tip" in seen and "face" not in seen and lying_on_face(Scene(env), book) is not None:
                seen.append("face")

        out = attempt(env, state, policy, 0, 520, 8, on_step=watch)
        assert "tip" in seen and "close" not in seen[:seen.index("tip")], seen  # tipped before any grasp
        assert "face" in seen, seen  # it lay on a face after the push
        assert out.success, out
    finally:
        env.close()


@pytest.mark.sim
def test_version_25_pushes_in_a_drawer_whose_front_stops_the_palm_on_its_way_down():
    """tunewide2, libero_90 KITCHEN_SCENE10 (the pudding into the top drawer), init 1, step
    155: the pudding stands 7 cm in front of the fully open top drawer. No part of the
    drawer is over it, but the palm reaches 10 cm along its closing axis: every grasp's hand
    stopped on the drawer's front 17 cm over the grip site (version 24: the same grasp four
    times, `retries_exhausted`). The drawer is now pushed in until the palm's way down is
    clear, the pudding set down far enough out that it stays clear once the drawer is open
    again, and it goes in."""
    task = "KITCHEN_SCENE10_put_the_chocolate_pudding_in_the_top_drawer_of_the_cabinet_and_close_it"
    region = "wooden_cabinet_1_top_region"
    with tuning_scene("libero_90", task, 1, 494856142, 155) as s:
        joint = s.env.region(region).joints[0]
        parts = s.env.joint_part_boxes(joint)
        assert s.box("chocolate_pudding_1").lo[1] - parts[:, 1, 1].max() > 0.02  # no part of the drawer over it
        assert checks.overhanging_drawer(s, "chocolate_pudding_1") == region
        out_before = abs(s.env.joint_position(joint))
    first_held = []  # how far out the drawer was when the pudding was first held

    def watch(env, _):
        def on_step(_):
            if not first_held and Scene(env).holding_any() == "chocolate_pudding_1":
                first_held.append(abs(env.joint_position(joint)))
        return on_step

    out = tuning_attempt("libero_90", task, 494856142, 155, init=1, watch=watch)
    assert first_held and first_held[0] < out_before - 0.03, (first_held, out_before)  # pushed in first
    assert out.success, out


@pytest.mark.sim
def test_version_25_takes_the_grasp_that_grazes_a_fixture_least_when_none_is_clear():
    """tunewide2, libero_goal "put the wine bottle on the rack", init 2, step 57: the bottle
    lies between the rack and the cabinet, a bowl beside it. With the bowl away no grasp's
    hand is clear: the rays' choice goes 2 cm into the rack, the grasps slid along the bottle
    clear of the rack meet the cabinet's edge by a few mm, and no push frees one. Version 24
    fell back on the rays' choice and stopped on the rack four times (`retries_exhausted`);
    `nudge.palm_graze` takes the slid grasp that grazes a fixture least, and the bottle goes
    onto the rack."""
    from pipeline.policies.scripted.placement import destination
    from pipeline.policies.scripted.recovery.nudge import palm_block, palm_clear, palm_graze, push_plan
    from tests.policies.failure_states import set_pose

    task, bottle = "put_the_wine_bottle_on_the_rack", "wine_bottle_1"
    with tuning_scene("libero_goal", task, 2, 343094286, 57) as s:
        set_pose(s.env, "akita_black_bowl_1", [0.3, 0.3, s.table_height() + 0.05])  # out of the way
        dest = destination(s, bottle, "wine_rack_1_top_region")
        assert palm_clear(s, bottle, dest, 1) is None and push_plan(s, bottle, dest) is None
        _, g = palm_graze(s, bottle, dest, 1)
        assert palm_block(s, bottle, g) == ["wooden_cabinet_1"]  # the rack clear, the cabinet grazed
    out = tuning_attempt("libero_goal", task, 343094286, 57, init=2)
    assert out.success, out


@pytest.mark.sim
def test_version_25_leaves_a_bowl_beside_the_low_drawers_sweep_where_a_grasp_stays_clear():
    """tunebooks, libero_10 KITCHEN_SCENE4 (the bowl into the bottom drawer), init 3, step 55:
    the bowl stands 2.5 cm before the shut bottom drawer's sweep, the wine rack behind it.
    The drawer is low (its floor below the bowl's rim), so version 24 set the bowl aside
    before opening: no free spot near, it was carried 33 cm off and back and the drawer was
    still to close at the horizon (a timeout). Beside the sweep, with grasps whose palm
    comes down clear of the opened drawer, it now stays (`checks.sweep_spares`), and the
    drawer opens, the bowl goes in and the drawer closes."""
    from pipeline.policies.scripted import articulated
    from pipeline.policies.scripted.grasps import plan_grasp

    task = "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it"
    with tuning_scene("libero_10", task, 3, 1471476559, 55) as s:
        joint = articulated.part_joint(s.env, "white_cabinet_1_bottom_region")
        sweep = checks.drawer_sweep(s, joint)
        assert checks.under_sweep(s, "akita_black_bowl_1", sweep)  # within a hand's reach of it
        assert checks.sweep_spares(s, "akita_black_bowl_1", joint, plan_grasp(s, "akita_black_bowl_1"))
    held = []
    out = tuning_attempt("libero_10", task, 1471476559, 55, init=3, watch=_watch_held(held))
    assert held == ["akita_black_bowl_1"], held  # held once: straight into the drawer, not set aside first
    assert out.success, out


@pytest.mark.sim
def test_version_26_swivels_a_face_down_book_whose_arm_would_come_down_on_the_caddy():
    """tunewide2, libero_90 STUDY_SCENE1 (left compartment), init 1, step 50: the book lies on
    its face before the caddy. Stood up by a corner pinch, the hand points level along the
    book's old up axis and the wrist links behind it came down on the caddy's wall: the book
    stalled 4.5 cm over the table, fell back on its face when let go, and the second stand
    came too late (version 25: a timeout). The lifted book is now swivelled first so that
    the arm clears the caddy (`face_book.arm_swivel`), it stands at once and goes in."""
    from pipeline.policies.scripted.primitives import axis_angle_matrix
    from pipeline.policies.scripted.recovery.face_book import SWIVELS, arm_meets, lying_on_face, turned_approach

    task = "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_left_compartment_of_the_caddy"
    with tuning_scene("libero_90", task, 1, 124104048, 50) as s:
        face = lying_on_face(s, "black_book_1")
        spot, a2 = s.box("black_book_1").centre[:2], turned_approach(face)
        assert arm_meets(s, "black_book_1", spot, face.height, a2) == ["desk_caddy_1"]
        up = np.array([0.0, 0.0, 1.0])
        assert not arm_meets(s, "black_book_1", spot, face.height, axis_angle_matrix(up, SWIVELS[0]) @ a2)
    out = tuning_attempt("libero_90", task, 124104048, 50, init=1)
    assert out.success, out


@pytest.mark.sim
def test_version_27_slides_a_face_down_book_off_the_caddys_wall_before_pinching_a_corner():
    """tunewide2, libero_90 STUDY_SCENE3 (right compartment), init 2, step 265: the book lies on
    its face against the caddy, and the hand's line at each top corner comes within 2 cm of
    the caddy's wall. Version 26 pinched anyway: the hand hovered against the wall for 85
    steps and closed on nothing, twice (a timeout). The fist now slides it clear first, along
    a push after which a corner's pinch is clear (`nudge.push_plan` with
    `face_book.pinch_clear_after`); then it is stood up and goes in."""
    from pipeline.policies.scripted.recovery.face_book import crowded_pinches, lying_on_face, pinch_clear_after
    from pipeline.policies.scripted.recovery.nudge import push_plan

    task = "STUDY_SCENE3_pick_up_the_book_and_place_it_in_the_right_compartment_of_the_caddy"
    with tuning_scene("libero_90", task, 2, 1866202764, 265) as s:
        face = lying_on_face(s, "black_book_1")
        assert crowded_pinches(s, "black_book_1", face)
        shove = push_plan(s, "black_book_1", None, frees=lambda d: pinch_clear_after(s, "black_book_1", face, d))
        assert shove is not None and pinch_clear_after(s, "black_book_1", face, shove.shift)
    out = tuning_attempt("libero_90", task, 1866202764, 265, init=2)
    assert out.success, out


@pytest.mark.sim
def test_version_28_grasps_a_book_on_its_side_pitched_less_where_the_turn_then_stays_in_reach():
    """tune26, libero_90 STUDY_SCENE4 (the middle book onto the shelf), init 4, step 344: the
    book lies on its side. Version 27 held its corner with the hand pitched 45 deg for the
    quarter turn and ran out of time (a timeout). Pitched 30 deg at the grasp, which the arm's
    chained reach (`SimEnv.ik_reach`: grasp, lift, turn) finds in reach here, the turn takes
    30 steps and the book is on the shelf before the horizon (398 steps, traced)."""
    from pipeline.policies.scripted.recovery.stand_book import NEAR_PITCH, stand_tilt, turn_first

    task = "STUDY_SCENE4_pick_up_the_book_in_the_middle_and_place_it_on_the_cabinet_shelf"
    with tuning_scene("libero_90", task, 4, 256230358, 344) as s:
        book = stand_tilt(s, "black_book_1")
        assert book is not None and turn_first(s, book)[1] == NEAR_PITCH
    out = tuning_attempt("libero_90", task, 256230358, 344)
    assert out.success, out


def _book_pose_attempt(task: str, init: int, kind: str, seed: int):
    """One recovery attempt (horizon 520) on a `benchmarks/book_poses.py` scene of a libero_90
    book task: (outcome, the primitive's label at each step)."""
    from benchmarks.book_poses import make_scene
    from pipeline.release.experts import attempt, recovery_expert
    from pipeline.sim import get_task

    env = build_env(get_task("libero_90", task))
    try:
        env.reset_to_init(init)
        state, _ = make_scene(env, kind, np.random.default_rng(seed))
        policy = recovery_expert(env, 0, 0.0)
        labels: list[str] = []
        out = attempt(env, state, policy, 0, 520, 8, on_step=lambda info: labels.append(getattr(policy._prim, "label", "")))
        return out, labels
    finally:
        env.close()


@pytest.mark.sim
def test_version_29_lets_the_hand_rise_toward_the_base_after_standing_a_book_up_from_its_face():
    """A tuning-state scene (`benchmarks/book_poses.py`, kind `upside`: libero_90 STUDY_SCENE2,
    the book into the back compartment, init state 0, seed 11020): tipped onto a face and
    stood up, the book is set down with the hand pointing toward the robot's base. Rising
    straight up while the hand levelled, the elbow stretched into its limit, the hand stayed
    tilted, and the arm was sent home (`back_out`'s pull-in) before the book was grasped: a
    timeout. Rising toward the base, the elbow stays bent and the hand levels on the way."""
    out, labels = _book_pose_attempt("STUDY_SCENE2_pick_up_the_book_and_place_it_in_the_back_compartment_of_the_caddy",
                                     0, "upside", 11020)
    assert "tip" in labels and "put_down" in labels, sorted(set(labels))
    assert "pull_in" not in labels[labels.index("put_down"):]
    assert out.success, out


@pytest.mark.sim
def test_version_30_tilts_the_hand_the_way_round_the_wrist_reaches_from_the_outset():
    """A tuning-state scene (`benchmarks/book_poses.py`, kind `side`: libero_90 STUDY_SCENE1,
    the book into the left compartment, init state 2, seed 17112): the book lies on its side.
    The hand tilted for its corner at the yaw `tilted_grasp` gives drove joint 7 into its
    limit and stalled the whole TILT_STEPS before turning by half a turn about its axis (104
    steps tilting; a timeout). The arm's reach (`SimEnv.ik_residual`) picks the turned yaw
    up front: one tilt, and the book is in the compartment before the horizon."""
    from pipeline.policies.scripted.recovery.stand_book import TILT_STEPS

    out, labels = _book_pose_attempt("STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_left_compartment_of_the_caddy",
                                     2, "side", 17112)
    assert 0 < labels.count("tilt") <= TILT_STEPS, labels.count("tilt")
    assert out.success, out


@pytest.mark.sim
def test_version_31_names_no_plan_for_a_lying_mug_the_microwave_takes_upright_only():
    """tunerecur, libero_10 KITCHEN_SCENE6 (the mug into the microwave), init 2, step 96: the
    mug lies on its side. The insertion grips an upright mug's handle and returned without a
    step five times: `retries_exhausted` at step 1, as if five grasps had failed. No skill
    stands a mug up, and from above it lands on the microwave's roof (tried): the expert
    says so, `no_plan`."""
    from pipeline.policies.scripted.recovery.lying_cup import lying

    task = "KITCHEN_SCENE6_put_the_yellow_and_white_mug_in_the_microwave_and_close_it"
    with tuning_scene("libero_10", task, 2, 1743900017, 96) as s:
        assert lying(s, "white_yellow_mug_1") and not lying(s, "porcelain_mug_1")
    policies = []

    def watch(_, policy):
        policies.append(policy)
        return None

    out = tuning_attempt("libero_10", task, 1743900017, 96, init=2, watch=watch)
    assert not out.success and out.steps <= 2, out
    assert policies[0].give_up_reason == GiveUpReason.NO_PLAN, policies[0].give_up_detail


@pytest.mark.sim
def test_version_32_presses_a_bowl_leaning_in_the_drawer_flat_instead_of_grasping_it_again():
    """tunewide, libero_10 KITCHEN_SCENE4 (the bowl into the bottom drawer and close it), init
    3, step 305: the bowl leans 35 degrees on the open drawer's wall and rises over it, so the
    drawer jams. Grasped again to be re-placed, the hand came down on the cabinet over the
    drawer's back half twice (a timeout; `retries_exhausted` with a longer horizon). A fist
    pressing its highest rim point, in the open, lays it flat, and the drawer closes."""
    from pipeline.policies.scripted.grasps import leaning

    task = "KITCHEN_SCENE4_put_the_black_bowl_in_the_bottom_drawer_of_the_cabinet_and_close_it"
    joint = "white_cabinet_1_bottom_level"
    with tuning_scene("libero_10", task, 3, 173332742, 305) as s:
        assert leaning(s, "akita_black_bowl_1") and checks.proud_in_drawer(s, joint) == ["akita_black_bowl_1"]
    labels: list[str] = []
    out = tuning_attempt("libero_10", task, 173332742, 305, init=3,
                         watch=lambda _, policy: lambda info: labels.append(getattr(policy._prim, "label", "")))
    assert "press" in labels and "close" not in labels[:labels.index("press")], sorted(set(labels))
    assert out.success, out
