"""BDDL normalization: one declaration line per type, nothing else changed, LIBERO agrees."""

from __future__ import annotations

from collections import Counter

import pytest

from pipeline.sim import all_tasks
from pipeline.sim.env import parse_bddl
from pipeline.stage2.bddl_normalize import normalize_bddl, section_declarations

SPLIT = """(define (problem LIBERO_Tabletop_Manipulation)
  (:domain robosuite)
  (:language put both bowls on the plate)
  (:fixtures
    main_table - table
  )
  (:objects
    akita_black_bowl_1 - akita_black_bowl
    plate_1 - plate
    akita_black_bowl_2 - akita_black_bowl
  )
  (:obj_of_interest
    akita_black_bowl_1
  )
  (:init
    (On plate_1 main_table_plate_region)
  )
  (:goal
    (And (On akita_black_bowl_1 plate_1) (On akita_black_bowl_2 plate_1))
  )
)
"""


def _parse_text(tmp_path, text: str, name: str) -> dict:
    path = tmp_path / name
    path.write_text(text)
    return parse_bddl(path)


def test_all_130_task_bddls_keep_objects_types_and_goal(tmp_path):
    tasks = all_tasks()
    assert len(tasks) == 130
    for t in tasks:
        text = t.bddl_path.read_text()
        norm = normalize_bddl(text)
        before, after = parse_bddl(t.bddl_path), _parse_text(tmp_path, norm, "n.bddl")
        for key in ("objects", "fixtures", "goal_state", "regions", "initial_state", "obj_of_interest"):
            assert before[key] == after[key], f"{t.task_id}: {key} changed"
        for head in (":objects", ":fixtures"):  # every declared (name, type) survives, once
            typed, untyped = section_declarations(text, head)
            assert Counter(typed) == Counter(section_declarations(norm, head)[0]), t.task_id
            types = [typ for _, typ in section_declarations(norm, head)[0]]
            assert len(set(types)) == len(dict.fromkeys(types)), t.task_id


def test_a_type_split_over_two_lines_loses_an_object_in_libero_until_normalized(tmp_path):
    before = _parse_text(tmp_path, SPLIT, "split.bddl")
    assert before["objects"]["akita_black_bowl"] == ["akita_black_bowl_2"]  # LIBERO's overwrite
    norm = normalize_bddl(SPLIT)
    assert "akita_black_bowl_1 akita_black_bowl_2 - akita_black_bowl" in norm
    after = _parse_text(tmp_path, norm, "norm.bddl")
    assert after["objects"] == {"akita_black_bowl": ["akita_black_bowl_1", "akita_black_bowl_2"], "plate": ["plate_1"]}
    assert after["goal_state"] == before["goal_state"]


def test_normalization_leaves_text_outside_the_declarations_byte_identical():
    norm = normalize_bddl(SPLIT)
    head, tail = SPLIT.split("  (:objects")[0], SPLIT.split("  (:obj_of_interest")[1]
    assert norm.startswith(head) and norm.endswith(tail)
    assert normalize_bddl(norm) == norm  # idempotent


def test_unbalanced_declarations_are_refused():
    with pytest.raises(ValueError, match="unbalanced"):
        normalize_bddl("(define (:objects a - b\n")
