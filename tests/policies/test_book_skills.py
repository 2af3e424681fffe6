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


@pytest.mark.sim
def test_a_moved_and_turned_book_goes_upright_into_the_front_compartment():
    from pipeline.policies.scripted.recovery import make_recovery_expert
    from pipeline.rollout import run_episode

    task = tasks(["libero_90"])[73]  # STUDY_SCENE1: the book into the caddy's front compartment
    env = build_env(task)
    try:
        start(env)
        sim = env.env.sim
        adr = env.free_joints()["black_book_1"]
        quat = _turned(np.array(sim.data.qpos[adr + 3 : adr + 7]), np.radians(35))
        set_pose(env, "black_book_1", env.object_pose("black_book_1")[0] + [0.05, 0.02, 0.0], quat)
        policy = make_recovery_expert(env, task, seed=0)
        result = run_episode(env, policy, horizon=300, chunk_size=8)
        assert result.success, policy.events
        lo, hi = env.object_aabb("black_book_1")
        assert hi[2] - lo[2] > 0.12  # standing, not lying across the compartments
    finally:
        env.close()
