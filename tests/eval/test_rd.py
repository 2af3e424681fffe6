from __future__ import annotations

import numpy as np
import pytest

from pipeline.eval.rd import gripper_commands, rd_starts, start_steps
from tests.eval.conftest import SCENE_STEP, motion


def test_start_steps_every_20_split_at_the_onset():
    assert start_steps(101, onset=45, every=20) == [(0, "pre"), (20, "pre"), (40, "pre"), (60, "post"),
                                                     (80, "post"), (100, "post")]
    assert start_steps(41, onset=40, every=20)[-1] == (40, "post")  # the onset state itself is post


def test_start_steps_reject_an_onset_outside_the_rollout():
    with pytest.raises(ValueError, match="outside"):
        start_steps(30, onset=30, every=20)


def test_gripper_command_in_force_follows_the_previous_action():
    a = np.zeros((3, 7))
    a[1, 6] = 1.0
    assert gripper_commands(a) == ["open", "open", "closed", "open"]


def test_rd_starts_read_a_recorded_rollout(fixture_run):
    starts = rd_starts(fixture_run.episode, onset=SCENE_STEP, every=20)
    assert [(s.start_step, s.phase) for s in starts] == [(0, "pre"), (20, "pre"), (40, "post"), (60, "post"),
                                                         (80, "post")]
    # the fixture closes the gripper from step 50 on
    assert [s.gripper for s in starts] == ["open", "open", "open", "closed", "closed"]
    assert len(motion()) == 80


def test_rd_starts_name_the_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="states.npy"):
        rd_starts(tmp_path, onset=0, every=20)
