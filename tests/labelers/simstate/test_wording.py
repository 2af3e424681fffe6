"""Recovery actions read as a person would say them, for every (level, category, task type)
over the goals of all 130 LIBERO tasks (parsed from their BDDL files, no simulator)."""

from __future__ import annotations

import re

import pytest

from pipeline.labelers.simstate.wording import recovery_action
from pipeline.records import Category, Level

VERBS = {"Grasp", "Pick", "Push", "Set", "Approach", "Move", "Put", "Take", "Open", "Close", "Turn", "Try"}


@pytest.fixture(scope="module")
def goals():
    from pipeline.sim.env import parse_bddl
    from pipeline.sim.registry import all_tasks

    out = []
    for t in all_tasks():
        p = parse_bddl(t.bddl_path)
        objects = [o for names in p["objects"].values() for o in names]
        fixtures = [f for names in p["fixtures"].values() for f in names]
        out.append((t.task_id, [list(c) for c in p["goal_state"]], objects, fixtures))
    assert len(out) == 130
    return out


def _problems(text: str, objects: list[str], fixtures: list[str]) -> list[str]:
    bad = []
    if not text or text[0].islower() or text.split()[0] not in VERBS:
        bad.append("does not start with a capitalized verb")
    if "_" in text or re.search(r"\b[a-z]+ \d+\b", text):
        bad.append("a BDDL name (underscore or a numbered instance)")
    if re.search(r"\b(the the|a the|the a|it it|and and)\b", text):
        bad.append("a doubled word")
    if re.search(r"of the flat stove|the cook\b|contain region|akita|chefmate|porcelain ramekin", text):
        bad.append("a region or maker name read literally")
    if any(kind in text for kind in ("main table", "wooden two layer")):
        bad.append("a raw fixture name")
    if text.endswith((" ", ",", ".")) or "  " in text:
        bad.append("stray spacing or punctuation")
    return bad


def test_every_level_category_and_task_type_gives_a_clean_imperative(goals):
    seen_types, failures = set(), []
    for task_id, goal, objects, fixtures in goals:
        moved = [c[1] for c in goal if c[0].lower() in ("on", "in")]
        parts = [c[1] for c in goal if c[0].lower() not in ("on", "in")]
        abouts = [(m, "pick_place") for m in moved] + [(p, "articulated") for p in parts]
        for about, task_type in abouts:
            seen_types.add(task_type)
            others = [o for o in objects if o != about and o not in moved]
            for level in Level:
                for category in Category:
                    for obstacle in ([None, others[0]] if others else [None]):
                        for toppled in (False, True):
                            text = recovery_action(level, category, goal, objects, fixtures, about, obstacle, toppled)
                            for p in _problems(text, objects, fixtures):
                                failures.append(f"{task_id} {level.value}/{category.value}/{task_type}: {p}: {text!r}")
    assert seen_types == {"pick_place", "articulated"}
    assert not failures, "\n".join(failures[:20])


def test_objects_are_named_as_people_do():
    goal = [["on", "akita_black_bowl_1", "plate_1"]]
    objects = ["akita_black_bowl_1", "akita_black_bowl_2", "plate_1"]
    assert recovery_action(Level.L2, Category.grasp_failure, goal, objects, ["main_table"], "akita_black_bowl_1") \
        == "Pick the black bowl up again and put it on the plate"
    assert recovery_action(Level.L4, Category.collision_or_interaction_failure, goal, objects, ["main_table"],
                           "akita_black_bowl_1", obstacle="akita_black_bowl_2") \
        == "Push the other black bowl aside, then grasp the black bowl and put it on the plate"


def test_regions_and_fixtures_read_as_places():
    fixtures = ["flat_stove_1", "wooden_cabinet_1", "main_table"]
    stove = [["turnon", "flat_stove_1"], ["on", "moka_pot_1", "flat_stove_1_cook_region"]]
    assert recovery_action(Level.L1, Category.grasp_failure, stove, ["moka_pot_1"], fixtures, "moka_pot_1") \
        == "Grasp the moka pot again and put it on the stove"
    assert recovery_action(Level.L1, Category.collision_or_interaction_failure, stove, ["moka_pot_1"], fixtures,
                           "flat_stove_1") == "Turn on the stove again"
    drawer = [["open", "wooden_cabinet_1_top_region"], ["in", "akita_black_bowl_1", "wooden_cabinet_1_top_region"]]
    assert recovery_action(Level.L3, Category.placement_failure, drawer, ["akita_black_bowl_1"], fixtures,
                           "akita_black_bowl_1", toppled=True) \
        == "Set the black bowl upright, then pick it up and put it in the top drawer of the cabinet"
    caddy = [["in", "black_book_1", "desk_caddy_1_back_contain_region"]]
    assert recovery_action(Level.L2, Category.placement_failure, caddy, ["black_book_1", "desk_caddy_1"], [],
                           "black_book_1").endswith("put it in the back compartment of the caddy, "
                                                    "lowering it before you let go")
