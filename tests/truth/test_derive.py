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


def _tipping_mug(rows_n=120, tip_from=40, tip_to=70):
    """Evidence of a mug (a goal target) tipping from 0 to 90 deg between two states, still
    (speed 0) before and after, nothing else moving."""
    import numpy as np

    from pipeline.evidence import Evidence

    t = np.arange(rows_n)
    frac = np.clip((t - tip_from) / (tip_to - tip_from), 0, 1)
    pos = np.stack([0.08 * frac, np.zeros(rows_n), 0.9 - 0.03 * frac], axis=1).astype(np.float32)
    speed = np.where((t >= tip_from) & (t < tip_to), 0.1, 0.0).astype(np.float32)
    cols = {"position": pos, "tilt_deg": (90 * frac).astype(np.float32), "lift": pos[:, 2] - 0.9,
            "speed": speed}
    still = {"position": np.tile([0.3, 0.0, 0.9], (rows_n, 1)).astype(np.float32), "tilt_deg": np.zeros(rows_n),
             "lift": np.zeros(rows_n), "speed": np.zeros(rows_n)}
    return Evidence(step=t, control_hz=20, gripper_opening=np.full(rows_n, 0.08), gripper_command=-np.ones(rows_n),
                    grasped=[""] * rows_n, contacts=[[] for _ in t], goal_progress=np.zeros(rows_n),
                    objects=["mug_1", "plate_1"], fixtures=["main_table"], goal=[["on", "mug_1", "plate_1"]],
                    targets=["mug_1"], references=["plate_1"],
                    per_object={c: {"mug_1": cols[c], "plate_1": still[c]} for c in cols})


def test_the_level_is_read_at_the_settled_scene_when_the_target_still_moves_after_the_attempt():
    """LIVING_ROOM_SCENE5's white mug (report10): 26 deg when the generator's attempt ended,
    70 deg and 9 cm off at the scene stage 2 releases. The record says L2; the scene is L3."""
    meta = {"objects": ["mug_1", "plate_1"], "fixtures": ["main_table"], "goal": [["on", "mug_1", "plate_1"]]}
    r = row(0, "dropped", step=40, obj="mug_1", release=0.02, changes=[change("mug_1", 0.02, tilt=26, gain=26)])
    r["target"], r["end_step"] = "mug_1", 50
    ev = _tipping_mug()
    t = derive("k", [r], meta, evidence=ev)
    assert (t.level, t.level_window, t.level_end_step) == ("L3", "scene", 70)
    assert derive("k", [r], meta).level == "L2"  # no evidence: the attempt's record, as before
    ended_later = dict(r, end_step=90)  # the attempt itself lasted past the settled scene: its record stands
    assert (derive("k", [ended_later], meta, evidence=ev).level_window,
            derive("k", [ended_later], meta, evidence=ev).level) == ("attempt", "L2")
