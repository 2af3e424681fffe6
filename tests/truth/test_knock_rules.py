"""The recorder's knock rules on a hand-made trace (no simulator): what counts as the
attempt's decisive knock, and what is a nudge the expert then gets past."""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.truth import Attempt, TruthLog

GOAL = [("on", "bowl_1", "plate_1"), ("open", "cabinet_1_top_region")]
UP = np.array([1.0, 0.0, 0.0, 0.0])


class _Env:
    fixture_names = ["cabinet_1", "main_table"]


class _Scene:
    env = _Env()


def trace(n: int = 60, moves: dict | None = None, sat=lambda t: (False, True)) -> TruthLog:
    """Bowl, plate and cup at rest, except `moves` {object: (from row, xy offset)}; the gripper
    closes at row 30."""
    log = TruthLog.__new__(TruthLog)
    log.scene, log.error = _Scene(), None
    log.objects, log.goal = ["bowl_1", "plate_1", "cup_1"], GOAL
    base = {"bowl_1": [0.0, 0.0, 0.9], "plate_1": [0.2, 0.0, 0.9], "cup_1": [0.0, 0.2, 0.9]}
    log.pos, log.quat, log.held, log.sat, log.eef = [], [], [], [], []
    for t in range(n + 1):
        rows = []
        for o in log.objects:
            p = np.array(base[o])
            if moves and o in moves and t >= moves[o][0]:
                p[:2] += moves[o][1]
            rows.append(p)
        log.pos.append(np.array(rows))
        log.quat.append(np.array([UP] * 3))
        log.held.append("")
        log.sat.append(sat(t))
        log.eef.append(np.zeros(3))
    log.cmd = [1.0 if t >= 30 else -1.0 for t in range(n)]
    return log


def attempt() -> Attempt:
    return Attempt(0, "pick_place", GOAL[0], "bowl_1", "plate_1", 0, phases=[("descend", 20), ("close", 30)])


def test_a_bystander_pushed_2_cm_is_knocked_but_the_target_nudged_3_cm_before_the_close_is_not():
    log = trace(moves={"cup_1": (10, [0.025, 0.0])})
    assert [k["object"] for k in log._knocks(attempt(), 60)] == ["cup_1"]
    log = trace(moves={"bowl_1": (10, [0.03, 0.0])})
    assert log._knocks(attempt(), 60) == []  # the expert then grasps it: the nudge is not its mistake
    log = trace(moves={"bowl_1": (10, [0.06, 0.0])})
    assert [k["object"] for k in log._knocks(attempt(), 60)] == ["bowl_1"]


def test_an_object_that_ends_where_the_goal_wants_it_is_not_knocked():
    log = trace(moves={"bowl_1": (40, [0.2, 0.0])}, sat=lambda t: (t >= 40, True))
    a = Attempt(0, "open", GOAL[1], "cabinet_1_top_region", None, 0)  # the bowl rides in the drawer
    assert log._knocks(a, 60) == []


def test_a_goal_conjunct_undone_during_another_attempt_is_an_undo_knock_at_the_first_false_state():
    log = trace(sat=lambda t: (False, t < 45))  # the open drawer bumped shut at row 45
    [k] = log._knocks(attempt(), 60)
    assert (k["object"], k["step"], k.get("undo")) == ("cabinet_1", 45, True)
