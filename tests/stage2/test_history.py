"""The pre-failure history: which steps it covers, and what a real run writes."""

import json

import numpy as np
import pytest

from pipeline.records import Localization
from pipeline.stage2.history import history_steps


def test_history_is_the_window_of_steps_just_before_the_onset():
    assert history_steps(20, 8, 1) == list(range(12, 20))


def test_history_near_the_start_holds_only_the_steps_that_exist():
    assert history_steps(3, 8, 1) == [0, 1, 2]
    assert history_steps(0, 8, 1) == []


def test_history_stride_spaces_the_observations():
    assert history_steps(20, 4, 5) == [0, 5, 10, 15]


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_the_history_holds_the_window_before_the_onset(stage2_run, stage1_run, episodes):
    rec = episodes["drop"]
    path = stage2_run / "stage2" / "localizations" / rec.suite / rec.task / f"{rec.episode_id}.json"
    loc = Localization.model_validate_json(path.read_text())
    h = np.load(stage2_run / "stage2" / loc.history)
    onset = loc.fail_step
    assert h["steps"].tolist() == list(range(onset - 8, onset))
    # rendered frames live beside it, apart from the byte-reproducible arrays
    assert "agentview" not in h.files
    f = np.load(stage2_run / "stage2" / loc.history.replace("_history.npz", "_history_frames.npz"))
    assert f["steps"].tolist() == h["steps"].tolist()
    assert f["agentview"].shape == (8, 224, 224, 3) and f["agentview"].std() > 10
    assert not np.array_equal(f["agentview"][0], f["agentview"][-1])  # the arm moved in between
    states = np.load(stage1_run / "stage1" / episodes["drop"].path / "states.npy")
    np.testing.assert_array_equal(h["sim_states"], states[onset - 8 : onset])
    assert h["actions"].shape == (8, 7) and h["eef_pos"].shape == (8, 3)
    assert json.loads(json.dumps(h["time_s"].tolist()))[-1] == pytest.approx((onset - 1) / 20)
