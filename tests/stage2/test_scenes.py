"""Scene pairs written by a real stage-2 run rebuild, restore, and are unfinished."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.errors import EpisodeError
from pipeline.records import Localization
from pipeline.sim import SimEnv, get_task
from pipeline.stage2.scenes import write_scene

pytestmark = [pytest.mark.sim, pytest.mark.xdist_group("stage2_rollouts")]


def _localizations(run):
    return [Localization.model_validate_json(p.read_text()) for p in sorted((run / "stage2" / "localizations").rglob("*.json"))]


def test_every_scene_rebuilds_from_its_bddl_restores_from_its_npy_and_is_unfinished(stage2_run):
    locs = _localizations(stage2_run)
    assert len(locs) == 3
    for loc in locs:
        bddl = stage2_run / "stage2" / loc.scene_bddl
        state = np.load(stage2_run / "stage2" / loc.scene_state)
        # the scene is the first settled state at or after the onset
        assert loc.scene_step >= loc.fail_step
        assert bddl.name == f"step_{loc.scene_step:04d}.bddl"
        assert bddl.with_name(f"step_{loc.scene_step:04d}_sim_state.npy").exists()
        spec = get_task(loc.suite, loc.task).model_copy(update={"bddl_path": bddl})
        with SimEnv(spec) as env:  # LIBERO builds the scene from the scene's own BDDL
            env.reset_to(state)
            np.testing.assert_allclose(env.get_state()[1:], state[1:], atol=1e-9)
            assert not env.goal_satisfied(), loc.key
            assert max(env.object_speeds().values()) < 0.01, f"{loc.key}: objects still moving in the scene"


def test_a_state_where_the_goal_holds_is_refused_as_a_scene(spatial_env, stage1_run, episodes, tmp_path):
    rec = episodes["success"]
    final = np.load(stage1_run / "stage1" / rec.path / "states.npy")[-1]
    with pytest.raises(EpisodeError) as err:
        write_scene(tmp_path, spatial_env, rec.suite, rec.task, rec.episode_id, rec.steps, final)
    assert err.value.reason == "goal_satisfied_at_onset"
    assert not any(tmp_path.rglob("*.npy"))


def test_a_state_of_the_wrong_length_is_refused(spatial_env, episodes, tmp_path):
    rec = episodes["drop"]
    with pytest.raises(EpisodeError) as err:
        write_scene(tmp_path, spatial_env, rec.suite, rec.task, rec.episode_id, 3, np.zeros(5))
    assert err.value.reason == "state_shape"
