"""The planner covers every goal of the 130 LIBERO tasks (BDDL level, no simulator)."""

from __future__ import annotations

import re
from collections import Counter

import pytest

from pipeline.policies.scripted.planner import PREDICATES, order_goal, skill_for
from pipeline.sim import all_tasks


def bddl_goal(text: str) -> list[tuple[str, ...]]:
    """Conjuncts of a BDDL file's `(:goal (And ...))`, lower-cased like SimEnv.goal."""
    body = text[text.index("(:goal") :]
    return [tuple(m.lower().split()) for m in re.findall(r"\(([A-Za-z]+ [^()]+)\)", body)]


@pytest.fixture(scope="module")
def goals() -> dict[str, list[tuple[str, ...]]]:
    return {t.task_id: bddl_goal(t.bddl_path.read_text()) for t in all_tasks()}


def drawer_opener(region: str) -> str | None:
    # what the live check answers for LIBERO's scenes: drawers and the microwave must open
    if re.search(r"cabinet_1_(top|middle|bottom)_region$", region):
        return region
    return "microwave_1" if region.startswith("microwave_1") else None


def test_goals_of_all_130_tasks_use_exactly_the_six_known_predicates(goals):
    assert len(goals) == 130
    kinds = Counter(c[0] for g in goals.values() for c in g)
    assert kinds == Counter({"in": 63, "on": 61, "close": 11, "turnon": 8, "open": 7, "turnoff": 1})


def test_every_conjunct_of_every_task_gets_a_skill(goals):
    for task_id, goal in goals.items():
        assert goal, f"{task_id}: empty goal"
        for c in goal:
            assert callable(skill_for(c)), f"{task_id}: {c}"


def test_plan_order_opens_before_putting_in_and_closes_last(goals):
    for task_id, goal in goals.items():
        steps = order_goal(goal, drawer_opener)
        assert set(goal) <= set(steps), task_id
        kinds = [c[0] for c in steps]
        for i, c in enumerate(steps):
            if c[0] == "in" and drawer_opener(c[2]):
                opened = drawer_opener(c[2])
                assert ("open", opened) in steps[:i], f"{task_id}: {c} before opening {opened}"
            if c[0] == "close":
                assert all(k == "close" for k in kinds[i:]), f"{task_id}: {kinds}"


def test_drawer_task_without_open_in_goal_gets_an_implied_open():
    goal = [("in", "akita_black_bowl_1", "wooden_cabinet_1_top_region")]
    assert order_goal(goal, drawer_opener) == [("open", "wooden_cabinet_1_top_region"), *goal]


def test_unknown_predicate_is_rejected_by_name():
    with pytest.raises(ValueError, match="'stack'"):
        skill_for(("stack", "a", "b"))
    assert set(PREDICATES) == {"on", "in", "open", "close", "turnon", "turnoff"}


def test_a_bowl_that_gets_another_on_it_goes_to_the_tray_first():
    stack = ("on", "akita_black_bowl_1", "akita_black_bowl_2")
    tray = ("in", "akita_black_bowl_2", "wooden_tray_1_contain_region")
    assert order_goal([stack, tray], drawer_opener) == [tray, stack]
