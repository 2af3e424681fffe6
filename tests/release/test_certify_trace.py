"""`benchmarks/certify_trace.py` replays the recovery expert's first try from one scene of a
run folder and says phase by phase what the robot touched, in the real simulator."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.certify_trace import main, scene_key, state_file
from tests.policies import tuning_scenes

TASK = "put_the_wine_bottle_on_the_rack"
EPISODE = "scripted-i02-s343094286"


def test_a_scene_key_is_read_as_the_report_lists_it_or_as_a_stage2_path():
    assert scene_key(f"libero_goal/{TASK}/{EPISODE}@57") == ("libero_goal", TASK, EPISODE, 57)
    assert scene_key(f"libero_goal/{TASK}/{EPISODE}/step_0057") == ("libero_goal", TASK, EPISODE, 57)
    with pytest.raises(SystemExit, match="suite/task/episode@step"):
        scene_key(f"libero_goal/{TASK}@57")


def test_a_missing_scene_names_what_was_looked_for(tmp_path):
    with pytest.raises(SystemExit, match=f"episode_{EPISODE}/step_0057_sim_state.npy"):
        state_file(tmp_path, "libero_goal", TASK, EPISODE, 57)


@pytest.mark.sim
def test_the_trace_lists_each_phase_and_what_the_hand_touched(tmp_path):
    """A tuning scene (the bottle between the rack and the cabinet, a bowl beside it): the
    expert first sets the bowl aside, so within 80 steps its fingers close on the bowl."""
    folder = tmp_path / "run" / "stage2" / "selected_bddl_scenes_libero_goal" / TASK / f"episode_{EPISODE}"
    folder.mkdir(parents=True)
    np.save(folder / "step_0057_sim_state.npy", tuning_scenes.load("libero_goal", TASK, 2, 343094286, 57))
    out = tmp_path / "trace"
    main([str(tmp_path / "run"), f"libero_goal/{TASK}/{EPISODE}@57", "--horizon", "80", "--frames", "1", "60",
          "--out", str(out)])
    record = json.loads(out.with_suffix(".json").read_text())
    phases = record["phases"]
    assert not record["success"] and record["reason"] == "timeout" and record["steps"] == 80
    # phases follow one another without a gap and cover the attempt
    assert [p["start"] for p in phases[1:]] == [p["start"] + p["steps"] for p in phases[:-1]]
    assert phases[0]["start"] == 0 and sum(p["steps"] for p in phases) == record["steps"]
    closes = [p for p in phases if p["label"] == "close"]
    assert closes and "akita_black_bowl_1" in closes[0]["touched"]
    assert "| close |" in out.with_suffix(".md").read_text()
    from PIL import Image

    assert Image.open(out.with_suffix(".png")).size == (2 * 256, 2 * 256)  # two steps, agent over wrist view
