"""Every one of the 130 tasks builds, resets to init state 0, and is not yet solved there."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.sim import SimEnv, all_tasks


@pytest.mark.sim
@pytest.mark.parametrize("task", all_tasks(), ids=lambda t: t.task_id)
def test_task_builds_resets_to_init_state_zero_and_goal_is_not_satisfied(task):
    with SimEnv(task) as env:
        init = task.init_states()[0]
        env.reset_to(init)
        assert env.state_dim == init.shape[0]
        # the restored state is the official one (time included)
        np.testing.assert_array_equal(env.get_state(), init)
        assert env.goal, "every task has a goal"
        assert not env.goal_satisfied()
        assert not all(ok for _, ok in env.goal_conjuncts())
