"""The expert's typed seams write what the strings wrote: goal conjuncts, failure notes,
truth outcomes; and its two tables (placement strategies, recovery rules) keep their order.
No simulator."""

from __future__ import annotations

import pytest

from pipeline.policies.scripted.goal import KNOB, PUT, Conjunct, Predicate
from pipeline.policies.scripted.notes import Halt, Note, Outcome
from pipeline.policies.scripted.planner import order_goal, skill_for
from pipeline.policies.scripted.recovery.reasons import GiveUpReason
from pipeline.policies.scripted.recovery.rules import RULES
from pipeline.policies.scripted.strategies import PLACEMENTS
from pipeline.policies.scripted.truth import OUTCOMES


def test_a_conjunct_is_the_plain_tuple_libero_evaluates():
    c = Conjunct.of(["on", "akita_black_bowl_1", "plate_1"])
    assert c == ("on", "akita_black_bowl_1", "plate_1") and hash(c) == hash(("on", "akita_black_bowl_1", "plate_1"))
    assert {("on", "akita_black_bowl_1", "plate_1"): True}[c]  # Scene.satisfied looks it up so
    assert repr(c) == repr(("on", "akita_black_bowl_1", "plate_1"))  # logs and details read as before
    assert " ".join(c) == "on akita_black_bowl_1 plate_1"  # truth.parquet's `conjunct`
    assert (c.predicate, c.subject, c.target) == (Predicate.ON, "akita_black_bowl_1", "plate_1")
    assert c.predicate in PUT and Conjunct("turnon", "flat_stove_1").predicate in KNOB
    assert Conjunct("open", "drawer").target is None


def test_an_unknown_predicate_is_named_when_the_goal_is_read():
    with pytest.raises(ValueError, match="'stack' is not one of"):
        Conjunct.of(["stack", "a", "b"])


def test_the_plain_planner_reads_typed_and_plain_conjuncts_alike():
    goal = [Conjunct("in", "bowl", "drawer_region"), Conjunct("close", "drawer_region")]
    steps = order_goal(goal, lambda region: "drawer_region")
    assert steps == [("open", "drawer_region"), ("in", "bowl", "drawer_region"), ("close", "drawer_region")]
    assert isinstance(steps[0], Conjunct) and steps[0].predicate is Predicate.OPEN
    assert skill_for(Conjunct("on", "a", "b")) is skill_for(("on", "a", "b"))


def test_a_note_prints_as_the_kind_colon_object_string_reports_kept():
    assert str(Note(Outcome.MISSED_GRASP, "bowl_1")) == "missed_grasp:bowl_1"
    assert str(Note(Outcome.DROPPED, "mug")) == "dropped:mug"
    assert str(Note(Halt.NO_STAGING_SPOT, "mug")) == "no_staging_spot:mug"
    assert str(Note(Halt.GIVE_UP, GiveUpReason.UNREACHABLE)) == f"give_up:{GiveUpReason.UNREACHABLE.value}"


def test_the_truth_outcomes_are_the_strings_truth_parquet_holds():
    assert OUTCOMES == ("achieved", "missed_grasp", "lost_grasp", "dropped", "misplaced", "knocked", "half_open",
                        "not_turned", "timeout")
    assert all(type(str(o)) is str and str(o) == o.value for o in OUTCOMES)


def test_the_placement_strategies_are_asked_in_their_order_and_each_has_applies_and_plan():
    assert [p.name for p in PLACEMENTS] == ["shelf", "tip_push", "slot", "slide_in", "lay_down"]
    assert all(callable(p.applies) and callable(p.plan) for p in PLACEMENTS)


def test_the_recovery_rules_end_with_an_attempt_that_always_applies():
    names = [r.name for r in RULES]
    assert names[0].startswith("goal object off the table") and names[-1] == "one attempt at the subgoal"
    assert RULES[-1].when(None) is True and RULES[-1].replan
    # only unwinding, letting go and backing out leave the round going
    assert [r.name for r in RULES if not r.replan] == ["a wrist joint is pinned at its limit",
                                                      "the hand closed on nothing",
                                                      "the arm touches something, sits low or awkwardly"]
