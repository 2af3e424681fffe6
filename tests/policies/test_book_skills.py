"""Books: a standing book's footprint is read right, and the recovery expert puts a book
that was moved and turned into the desk caddy's narrow front compartment (5.7 cm wide for
a 2.8 cm book) standing up, in the real simulator."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.policies.scripted.slot import footprint
from pipeline.sim import build_env, tasks
from tests.policies.failure_states import set_pose, start


def test_footprint_of_a_turned_slab_gives_its_long_axis_length_and_thickness():
    a = np.radians(30)
    u, v = np.array([np.cos(a), np.sin(a), 0]), np.array([-np.sin(a), np.cos(a), 0])
    corners = np.array([[0.1, 0.2, 0] + su * 0.055 * u + sv * 0.014 * v for su in (-1, 1) for sv in (-1, 1)])
    theta, length, thin, centre = footprint(corners)
    assert abs(theta - a) < np.radians(1.5)
    assert length == pytest.approx(0.11, abs=0.002) and thin == pytest.approx(0.028, abs=0.002)
    assert np.allclose(centre, [0.1, 0.2], atol=1e-3)


def _turned(quat_wxyz: np.ndarray, yaw: float) -> np.ndarray:
    """The orientation turned by `yaw` about the world's vertical (w-x-y-z quaternions)."""
    w1, z1 = np.cos(yaw / 2), np.sin(yaw / 2)
    w, x, y, z = quat_wxyz
    return np.array([w1 * w - z1 * z, w1 * x - z1 * y, w1 * y + z1 * x, w1 * z + z1 * w])


def _expert_puts_the_book_in_standing(env, task) -> None:
    """The recovery expert, from the scene as it is now, meets the goal within 300 steps with
    the book standing (not lying across the compartments)."""
    from pipeline.policies.scripted.recovery import make_recovery_expert
    from pipeline.rollout import run_episode

    policy = make_recovery_expert(env, task, seed=0)
    result = run_episode(env, policy, horizon=300, chunk_size=8)
    assert result.success, policy.events
    lo, hi = env.object_aabb("black_book_1")
    assert hi[2] - lo[2] > 0.12


@pytest.mark.sim
def test_a_moved_and_turned_book_goes_upright_into_the_front_compartment():
    task = tasks(["libero_90"])[73]  # STUDY_SCENE1: the book into the caddy's front compartment
    env = build_env(task)
    try:
        start(env)
        sim = env.env.sim
        adr = env.free_joints()["black_book_1"]
        quat = _turned(np.array(sim.data.qpos[adr + 3 : adr + 7]), np.radians(35))
        set_pose(env, "black_book_1", env.object_pose("black_book_1")[0] + [0.05, 0.02, 0.0], quat)
        _expert_puts_the_book_in_standing(env, task)
    finally:
        env.close()


def test_the_tilted_hand_closes_across_a_leaning_books_faces_and_points_down_its_spine_axis():
    from pipeline.policies.scripted.primitives import hand_orientation
    from pipeline.policies.scripted.recovery.stand_book import BookAxes, tilted_grasp

    # the book of a released scene, leaning 52 deg across the caddy (its faces tilted too)
    up, thin = np.array([0.002, 0.789, 0.615]), np.array([-0.781, -0.383, 0.494])
    up, thin = up / np.linalg.norm(up), thin - (thin @ up) * up / np.linalg.norm(up)
    thin /= np.linalg.norm(thin)
    ax = BookAxes(up=up, thin=thin, top_mid=np.zeros(3), long=np.cross(thin, up), ends=(np.zeros(3), np.zeros(3)))
    yaw, approach = tilted_grasp(ax)
    hand = hand_orientation(yaw, approach)
    assert abs(abs(hand[:, 0] @ thin) - 1) < 1e-6  # fingers close along the faces' normal
    assert np.allclose(hand[:, 2], -up, atol=1e-6)  # the hand points down the book's up axis
    # turned back to pointing down at the same yaw, the book held so would stand upright
    turn = hand_orientation(yaw) @ hand.T
    assert np.allclose(turn @ up, [0, 0, 1], atol=1e-6)


@pytest.mark.sim
def test_a_book_leaning_across_the_caddy_is_stood_up_in_the_hand_and_goes_into_the_back_compartment():
    from pipeline.policies.scripted.recovery.stand_book import stand_tilt
    from pipeline.policies.scripted.scene import Scene

    task = tasks(["libero_10"])[5]  # STUDY_SCENE1: the book into the caddy's back compartment
    env = build_env(task)
    try:
        start(env)
        # the pose of a released failure: fallen across the right compartment, 52 deg off
        # upright, its faces tilted too; every top-down grasp of it missed
        set_pose(env, "black_book_1", [-0.381, -0.059, 1.039], np.array([-0.297, 0.146, 0.414, 0.848]), settle=40)
        assert stand_tilt(Scene(env), "black_book_1") is not None
        _expert_puts_the_book_in_standing(env, task)
    finally:
        env.close()
