"""The derivation rules of pipeline/truth/derive.py on hand-written attempt rows."""

from __future__ import annotations

import pytest

from pipeline.truth.derive import TruthError, derive

META = {"objects": ["bowl_1", "plate_1", "mug_1"], "fixtures": ["main_table"], "goal": [["on", "bowl_1", "plate_1"]]}


def change(obj, moved=0.0, pos=(0.0, 0.0, 0.9), tilt=0.0, gain=0.0, held=False, fell=False):
    return {"object": obj, "moved_m": moved, "tilt_deg": tilt, "tilt_gain_deg": gain, "fell_off": fell,
            "held": held, "position": list(pos)}


def row(attempt, outcome, step=40, obj="bowl_1", changes=(), release=None):
    return {"attempt": attempt, "skill": "pick_place", "outcome": outcome, "event": "x", "event_step": step,
            "event_object": obj, "target": "bowl_1", "changes": list(changes), "knocked": [],
            "release_dist_m": release, "detail": ""}


def test_the_first_failed_attempt_gives_onset_category_and_level():
    rows = [row(0, "achieved", None), row(1, "misplaced", 130, release=0.06,
                                          changes=[change("bowl_1", 0.02)]), row(2, "missed_grasp", 200)]
    t = derive("k", rows, META)
    assert (t.onset_step, t.onset_time_s, t.outcome, t.category, t.level) == (130, 6.5, "misplaced",
                                                                               "placement_failure", "L2")


PHASES = [{"label": "close", "step": 10}, {"label": "pick_lift", "step": 20}, {"label": "transport", "step": 30},
          {"label": "lower", "step": 50}, {"label": "open", "step": 60}]


@pytest.mark.parametrize("release, step, category", [
    (0.05, 40, "placement_failure"),  # in transit, but over the reference already
    (0.3, 40, "grasp_failure"),  # in transit, far from it: a drop in transit
    (0.3, 25, "grasp_failure"),
    (0.101, 55, "placement_failure"),  # while lowering over a place 10 cm off: a placement
    (0.3, 62, "placement_failure"),
])
def test_a_drop_while_placing_or_near_the_reference_is_a_placement_failure_in_transit_a_grasp_failure(
        release, step, category):
    rows = [row(0, "dropped", step=step, release=release, changes=[change("bowl_1", 0.12)])]
    rows[0]["phases"] = PHASES
    t = derive("k", rows, META)
    assert (t.category, t.level) == (category, "L3")


def test_knocking_a_bystander_next_to_the_plate_is_a_collision_and_an_obstruction():
    rows = [row(0, "knocked", obj="mug_1", changes=[change("mug_1", 0.04, pos=(0.05, 0, 0.9)),
                                                    change("plate_1", 0.0, pos=(0.0, 0.0, 0.9))])]
    t = derive("k", rows, META)
    assert (t.category, t.level) == ("collision_or_interaction_failure", "L4")
    rows[0]["event_object"] = "bowl_1"
    rows[0]["changes"] = [change("bowl_1", 0.06)]
    assert (derive("k", rows, META).category, derive("k", rows, META).level) == ("object_displacement", "L3")


@pytest.mark.parametrize("rows, reason", [([row(0, "achieved", None)], "no_failed_attempt"),
                                          ([row(0, "timeout", 0)], "timeout"), ([], "no_failed_attempt")])
def test_episodes_without_a_mistake_to_localize_are_set_aside_with_a_reason(rows, reason):
    with pytest.raises(TruthError) as e:
        derive("k", rows, META)
    assert e.value.reason == reason
