from __future__ import annotations

from collections import Counter

import numpy as np

from pipeline.sim.registry import all_tasks, get_task, tasks


def test_registry_has_the_130_tasks_of_the_five_suites():
    counts = Counter(t.suite for t in all_tasks())
    assert counts == {"libero_spatial": 10, "libero_object": 10, "libero_goal": 10, "libero_10": 10, "libero_90": 90}


def test_every_task_has_its_bddl_file_and_init_states_on_disk():
    for t in all_tasks():
        assert t.bddl_path.is_file(), t.bddl_path
        assert t.init_states_path.is_file(), t.init_states_path
        assert t.instruction and t.instruction == t.instruction.strip()


def test_task_names_are_unique_within_a_suite_and_indices_follow_libero_order():
    for suite in ("libero_spatial", "libero_object", "libero_goal", "libero_10", "libero_90"):
        ts = tasks([suite])
        assert len({t.name for t in ts}) == len(ts)
        assert [t.index for t in ts] == list(range(len(ts)))


def test_init_states_are_fifty_flat_float_vectors():
    t = tasks(["libero_spatial"])[0]
    states = t.init_states()
    assert states.shape[0] == 50 and states.ndim == 2
    assert states.dtype == np.float64 and np.isfinite(states).all()


def test_filtering_by_an_unknown_task_name_names_it():
    try:
        tasks(["libero_goal"], ["no_such_task"])
    except KeyError as e:
        assert "no_such_task" in str(e)
    else:
        raise AssertionError("expected KeyError")
    t = tasks(["libero_goal"])[3]
    assert get_task("libero_goal", t.name) == t
