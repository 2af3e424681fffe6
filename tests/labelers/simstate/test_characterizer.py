"""The simstate characterizer on what stage 2 wrote for real rollouts."""

from __future__ import annotations

import pytest

from pipeline.labelers.simstate.characterizer import characterize, readable
from pipeline.evidence import read_evidence
from pipeline.records import Category, Level, Localization


def _load(stage2_run, rec):
    path = stage2_run / "stage2" / "localizations" / rec.suite / rec.task / f"{rec.episode_id}.json"
    loc = Localization.model_validate_json(path.read_text())
    return loc, read_evidence(stage2_run / "stage2" / loc.evidence)


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_dropped_target_is_an_l3_grasp_failure_with_a_regrasp_action(stage2_run, episodes):
    c = characterize(*_load(stage2_run, episodes["drop"]))
    assert (c.recovery_level, c.failure_category, c.source) == (Level.L3, Category.grasp_failure, "simstate")
    assert c.recovery_action == "Re-grasp the akita black bowl 1 and place it on the plate"


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_missed_grasp_that_changed_nothing_is_l1(stage2_run, episodes):
    c = characterize(*_load(stage2_run, episodes["miss"]))
    assert (c.recovery_level, c.failure_category) == (Level.L1, Category.grasp_failure)


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_bowl_knocked_next_to_the_target_is_an_l4_obstruction_named_in_the_action(stage2_run, episodes):
    c = characterize(*_load(stage2_run, episodes["knock"]))
    assert c.recovery_level is Level.L4
    assert c.failure_category is Category.collision_or_interaction_failure
    assert c.recovery_action.startswith("Move the akita black bowl 2 out of the way")


@pytest.mark.sim
@pytest.mark.xdist_group("stage2_rollouts")
def test_a_vlm_onset_without_a_nearby_event_has_category_other(stage2_run, episodes):
    loc, ev = _load(stage2_run, episodes["miss"])
    far = loc.model_copy(update={"fail_step": 140, "fail_time_s": 7.0, "source": "openai"})
    assert characterize(far, ev).failure_category is Category.other
    near = loc.model_copy(update={"fail_step": loc.fail_step + 6, "fail_time_s": loc.fail_time_s + 0.3})
    assert characterize(near, ev).failure_category is Category.grasp_failure


def test_readable_names_drop_instance_numbers_unless_two_objects_share_a_kind():
    assert readable("plate_1", ["plate_1", "akita_black_bowl_1"]) == "plate"
    assert readable("akita_black_bowl_2", ["akita_black_bowl_1", "akita_black_bowl_2"]) == "akita black bowl 2"
    assert readable("main_table") == "table"
