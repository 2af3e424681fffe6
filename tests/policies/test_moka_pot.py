"""A moka pot turned about its vertical axis is still taken by its handle (real simulator,
LIBERO kitchen scene 8): in world boxes a turned handle is not thin, and the rim grasps
tried instead closed on air (a released L1 scene, retries exhausted)."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.policies.scripted.grasps import handle_grasp

from pipeline.policies.scripted.hand import closing_axis
from pipeline.policies.scripted.scene import Scene
from pipeline.sim import build_env, tasks
from tests.policies.failure_states import set_pose, start

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("moka_pot")]
POT = "moka_pot_1"


def turned(quat: np.ndarray, yaw: float) -> np.ndarray:
    """w-x-y-z quaternion `quat` turned by `yaw` about the world's vertical."""
    w1, z1 = np.cos(yaw / 2), np.sin(yaw / 2)
    w2, x2, y2, z2 = quat
    return np.array([w1 * w2 - z1 * z2, w1 * x2 - z1 * y2, w1 * y2 + z1 * x2, w1 * z2 + z1 * w2])


def test_a_turned_moka_pot_is_grasped_across_its_handle():
    with build_env(tasks(["libero_10"])[8]) as env:  # put both moka pots on the stove
        start(env)
        s = Scene(env)
        before = handle_grasp(s, POT)
        assert before is not None and abs(abs(before.yaw) - np.pi / 2) < 0.05  # unturned: across x, as always
        pos, quat = env.object_pose(POT)
        set_pose(env, POT, pos, turned(quat, np.radians(25)))
        g = handle_grasp(s, POT)
        assert g is not None
        rot = env.env.sim.data.body_xmat[env.env.obj_body_id[POT]].reshape(3, 3)
        # the fingers close across the handle's thin side (the pot's own x axis) ...
        assert abs(float(closing_axis(g.yaw) @ rot[:, 0])) > 0.99
        # ... on the handle, beside the body
        body = env.object_pose(POT)[0]
        assert 0.05 < float(np.linalg.norm(g.pos[:2] - body[:2])) < 0.09
