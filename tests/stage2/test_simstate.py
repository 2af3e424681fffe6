"""The simstate localizer on real rollouts with known failure moments."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.labelers.simstate.localizer import localize
from tests.stage2.rollouts import OTHER_BOWL, TARGET, plan_step

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("stage2_rollouts")]
HALF_SECOND = 10  # steps at 20 Hz


def test_dropped_bowl_is_localized_within_half_a_second_of_the_release(evidences, stage1_run):
    res = localize(evidences["drop"])
    truth = plan_step(stage1_run, "drop", 6)  # the open command mid-air
    assert abs(res.onset_step - truth) <= HALF_SECOND
    assert res.onset_event.kind == "object_dropped" and res.onset_event.object == TARGET


def test_missed_grasp_is_localized_at_the_close_command(evidences, stage1_run):
    res = localize(evidences["miss"])
    truth = plan_step(stage1_run, "miss", 3)  # gripper closes 6 cm above the rim
    assert abs(res.onset_step - truth) <= HALF_SECOND
    assert res.onset_event.kind == "grasp_missed" and res.onset_event.object == TARGET


def test_knocked_bowl_is_localized_when_it_starts_moving(evidences, stage1_run, episodes, spatial_env):
    states = np.load(stage1_run / "stage1" / episodes["knock"].path / "states.npy")
    adr = spatial_env.free_joints()[OTHER_BOWL]
    xyz = states[:, 1 + adr : 1 + adr + 3]
    truth = int(np.flatnonzero(np.linalg.norm(xyz - xyz[0], axis=1) > 1e-3)[0])  # straight from the log
    res = localize(evidences["knock"])
    assert abs(res.onset_step - truth) <= HALF_SECOND
    assert res.onset_event.object == OTHER_BOWL


def test_idle_episode_has_no_failure_event_and_falls_back_to_its_idle_start(evidences):
    res = localize(evidences["idle"])
    assert res.onset_step is None and res.events == []
    assert res.fallback_step == 0


def test_successful_episode_shows_no_failure_event(evidences):
    assert localize(evidences["success"]).events == []
