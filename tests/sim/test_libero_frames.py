"""Our frames against LIBERO's own: the same restored state drawn by `OffScreenRenderEnv`
(robosuite's offscreen context, LIBERO's observation path) and by us, pixel for pixel.

One task per kind of scene: a tabletop, the floor, an articulated fixture, a kitchen, a
living room and a study. The state is mid-episode (arm moved, gripper closing), restored in
plain LIBERO as the dataset card says (`np.random.seed(0)`, `reset()`, `set_init_state`).
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sim import SimEnv
from pipeline.sim.registry import get_task
from pipeline.sim.render import CAMERAS
from pipeline.sim.state_render import StateRenderer, reset_fields, save_model

SCENES = [
    ("libero_spatial", "pick_up_the_black_bowl_between_the_plate_and_the_ramekin_and_place_it_on_the_plate"),
    ("libero_object", "pick_up_the_alphabet_soup_and_place_it_in_the_basket"),
    ("libero_goal", "open_the_middle_drawer_of_the_cabinet"),
    ("libero_10", "KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it"),
    ("libero_90", "LIVING_ROOM_SCENE1_pick_up_the_alphabet_soup_and_put_it_in_the_basket"),
    ("libero_90", "STUDY_SCENE1_pick_up_the_book_and_place_it_in_the_front_compartment_of_the_caddy"),
]
SIZES = (128, 256)


def mid_episode_state(env: SimEnv) -> np.ndarray:
    """Init state 0, then 30 steps down and forward with the gripper closing."""
    env.reset_to_init(0)
    for t in range(30):
        env.step(np.array([0.3, 0.1, -0.4, 0.0, 0.0, 0.2, 1.0 if t > 15 else -1.0]))
    return env.get_state()


def libero_frames(task, state: np.ndarray) -> dict[tuple[str, int], np.ndarray]:
    """LIBERO's own frames of `state`: its observation at 128 px and robosuite's `sim.render`
    (the call that observation makes) at 256 px, flipped right side up."""
    from libero.libero.envs import OffScreenRenderEnv

    env = OffScreenRenderEnv(bddl_file_name=str(task.bddl_path), camera_heights=SIZES[0], camera_widths=SIZES[0])
    try:
        np.random.seed(0)
        env.reset()
        obs = env.set_init_state(state)
        assert np.array_equal(env.get_sim_state(), state)
        out = {(cam, SIZES[0]): obs[f"{cam}_image"][::-1] for cam in CAMERAS}
        for cam in CAMERAS:
            out[(cam, SIZES[1])] = env.env.sim.render(camera_name=cam, width=SIZES[1], height=SIZES[1])[::-1]
        return out
    finally:
        env.close()


@pytest.mark.sim
@pytest.mark.parametrize("suite,name", SCENES, ids=[f"{s}-{n[:24]}" for s, n in SCENES])
def test_standard_frames_equal_libero_offscreen_frames_for_both_cameras(suite, name, tmp_path):
    task = get_task(suite, name)
    with SimEnv(task) as env:
        state = mid_episode_state(env)
        theirs = libero_frames(task, state)
        env.set_state(state)
        save_model(env, tmp_path / "model.mjb")  # the stage-1 render process's path too
        renderer = StateRenderer(tmp_path / "model.mjb")
        try:
            for (cam, size), want in theirs.items():
                ours = env.render(cam, size, "standard")
                diff = np.abs(ours.astype(int) - want.astype(int))
                assert diff.max() == 0, (f"{suite}/{name} {cam} {size}px: {(diff.max(-1) > 0).mean():.1%} of pixels "
                                         f"differ from LIBERO's frame (mean {diff.mean():.2f}, max {diff.max()})")
                logged = renderer.render_states(state[None], [cam], size, "standard", reset_fields(env))[cam][0]
                assert np.array_equal(logged, want), f"{cam} {size}px: the render process's frame differs from LIBERO's"
            # fast quality is for people and VLMs: close to LIBERO's frame, never equal (no MSAA)
            fast = env.render("agentview", SIZES[1], "fast").astype(int)
            d = np.abs(fast - theirs[("agentview", SIZES[1])].astype(int))
            assert 0 < d.mean() < 4, f"fast frame is {d.mean():.2f}/255 from LIBERO's on average"
        finally:
            renderer.close()


@pytest.mark.sim
def test_openpi_observation_equals_what_openpis_libero_example_builds_from_libero():
    """openpi's examples/libero/main.py: LIBERO's env at 256 px, images `[::-1, ::-1]`,
    `resize_with_pad` to 224, state = eef pos, axis-angle of robosuite's eef quat, gripper qpos."""
    from libero.libero.envs import OffScreenRenderEnv
    from openpi_client import image_tools

    from pipeline.config import OpenpiPolicyConfig
    from pipeline.policies.openpi_policy import CAMERAS as OPENPI_CAMERAS
    from pipeline.policies.openpi_policy import openpi_request, quat_xyzw_to_axis_angle
    from pipeline.rollout import observe

    cfg = OpenpiPolicyConfig()
    task = get_task(*SCENES[0])
    with SimEnv(task) as env:
        state = mid_episode_state(env)
        lib = OffScreenRenderEnv(bddl_file_name=str(task.bddl_path), camera_heights=cfg.env_resolution,
                                 camera_widths=cfg.env_resolution)
        try:
            np.random.seed(0)
            lib.reset()
            obs = lib.set_init_state(state)
        finally:
            lib.close()
        env.set_state(state)

        class Client:  # what rollout.observe asks of an image policy
            cameras, image_size = OPENPI_CAMERAS, cfg.env_resolution

        ours = openpi_request(observe(env, Client(), 0), cfg)

    def example(img):
        return image_tools.convert_to_uint8(image_tools.resize_with_pad(np.ascontiguousarray(img[::-1, ::-1]), 224, 224))

    assert np.array_equal(ours["observation/image"], example(obs["agentview_image"]))
    assert np.array_equal(ours["observation/wrist_image"], example(obs["robot0_eye_in_hand_image"]))
    want = np.concatenate([obs["robot0_eef_pos"], quat_xyzw_to_axis_angle(obs["robot0_eef_quat"]),
                           obs["robot0_gripper_qpos"]])
    assert np.array_equal(ours["observation/state"], want.astype(np.float32))
    assert ours["prompt"] == task.instruction
