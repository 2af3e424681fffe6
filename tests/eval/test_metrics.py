from __future__ import annotations

import math

import pytest

from pipeline.eval.metrics import counts, rc, rd, rsr, select, task_rates
from pipeline.eval.records import MetricRow


def row(success: bool, suite="libero_spatial", task="t0", level="L1", gripper="open", mode="scene",
        scene="s0", rd_phase=None, policy="scripted", chunk_size=8) -> MetricRow:
    return MetricRow(success=success, suite=suite, task=task, level=level, gripper=gripper, mode=mode, scene_id=scene,
                     rd_phase=rd_phase, policy=policy, chunk_size=chunk_size)


@pytest.fixture
def rows() -> list[MetricRow]:
    # task a (L1, spatial): 3/4 ; task b (L2, spatial): 1/4 ; task c (L1, goal): 0/2
    return (
        [row(True, task="a", gripper="open"), row(True, task="a", gripper="open"),
         row(True, task="a", gripper="closed"), row(False, task="a", gripper="closed")]
        + [row(True, task="b", level="L2"), row(False, task="b", level="L2"),
           row(False, task="b", level="L2", gripper="closed"), row(False, task="b", level="L2", gripper="closed")]
        + [row(False, suite="libero_goal", task="c"), row(False, suite="libero_goal", task="c", gripper="closed")]
        # RD reruns must never count towards RSR
        + [row(True, task="a", mode="rd", rd_phase="pre")] * 5
    )


def test_rsr_overall_counts_scene_trials_only(rows):
    assert rsr(rows) == pytest.approx(4 / 10)
    assert counts(rows) == (4, 10)


def test_rsr_per_level_suite_and_gripper_match_hand_counts(rows):
    assert rsr(rows, level="L1") == pytest.approx(3 / 6)
    assert rsr(rows, level="L2") == pytest.approx(1 / 4)
    assert rsr(rows, suite="libero_goal") == 0.0
    assert rsr(rows, suite="libero_spatial", level="L2") == pytest.approx(1 / 4)
    assert rsr(rows, gripper="open") == pytest.approx(3 / 5)
    assert rsr(rows, gripper="closed") == pytest.approx(1 / 5)


def test_rsr_of_an_empty_subset_is_nan_not_zero(rows):
    assert math.isnan(rsr(rows, level="L4"))
    assert math.isnan(rsr([]))
    assert math.isnan(rsr(rows, suite="libero_goal", level="L2"))


def test_select_accepts_a_set_of_values(rows):
    assert len(select(rows, mode="scene", task={"a", "c"})) == 6


def test_task_rates_are_the_per_task_success_rates(rows):
    assert task_rates(rows) == {("libero_goal", "c"): 0.0, ("libero_spatial", "a"): 0.75,
                                ("libero_spatial", "b"): 0.25}


def test_rc_is_one_minus_population_std_of_task_rates(rows):
    rates = [0.75, 0.25, 0.0]
    mean = sum(rates) / 3
    std = math.sqrt(sum((x - mean) ** 2 for x in rates) / 3)  # population std by hand: 0.3118
    assert rc(rows) == pytest.approx(1 - std)
    assert rc(rows) == pytest.approx(0.688196, abs=1e-6)
    # within one suite: tasks a and b, rates 0.75 and 0.25 -> std 0.25
    assert rc(rows, suite="libero_spatial") == pytest.approx(0.75)


def test_rc_of_a_single_task_is_one_and_of_no_task_is_nan(rows):
    assert rc(rows, task="a") == 1.0
    assert math.isnan(rc(rows, level="L4"))


def _rd_rows(scene: str, pre: list[bool], post: list[bool], suite="libero_spatial") -> list[MetricRow]:
    return ([row(s, mode="rd", rd_phase="pre", scene=scene, suite=suite) for s in pre]
            + [row(s, mode="rd", rd_phase="post", scene=scene, suite=suite) for s in post])


def test_rd_matches_the_hand_computed_value_with_epsilon():
    rows = _rd_rows("s1", [True, True, False, True], [False, True]) + _rd_rows("s2", [True, False], [False, False])
    # pooled over matched scenes: M_pre = 4/6, M_post = 1/4
    res = rd(rows, epsilon=1e-3)
    assert (res.m_pre, res.m_post, res.n_pre, res.n_post, res.scenes) == (pytest.approx(4 / 6), 0.25, 6, 4, 2)
    assert res.rd == pytest.approx(1 - (0.25 + 1e-3) / (4 / 6 + 1e-3))
    assert res.rd == pytest.approx(0.624064, abs=1e-6)  # 1 - 0.251 / 0.667667


def test_rd_epsilon_keeps_zero_over_zero_finite_and_matters_when_m_pre_is_zero():
    never = _rd_rows("s1", [False, False], [False])
    assert rd(never, epsilon=1e-3).rd == 0.0
    # M_pre = 0, M_post = 1: RD = 1 - (1 + eps) / eps, strongly negative, and eps decides how much
    better = _rd_rows("s1", [False], [True])
    assert rd(better, epsilon=0.5).rd == pytest.approx(1 - 1.5 / 0.5)
    assert rd(better, epsilon=1e-3).rd == pytest.approx(1 - 1.001 / 0.001)


def test_rd_counts_only_scenes_with_both_phases():
    rows = _rd_rows("s1", [True], [False]) + _rd_rows("only_pre", [False, False, False], [])
    res = rd(rows, epsilon=1e-3)
    assert (res.m_pre, res.m_post, res.scenes) == (1.0, 0.0, 1)


def test_rd_of_an_empty_or_unmatched_subset_is_nan():
    assert math.isnan(rd([], epsilon=1e-3).rd)
    assert math.isnan(rd(_rd_rows("s1", [True], []), epsilon=1e-3).rd)
    rows = _rd_rows("s1", [True], [False])
    assert math.isnan(rd(rows, epsilon=1e-3, suite="libero_goal").rd)


def test_rd_rejects_a_non_positive_epsilon():
    with pytest.raises(ValueError, match="epsilon"):
        rd(_rd_rows("s1", [True], [False]), epsilon=0)


def test_rows_are_typed_so_a_filter_on_a_column_they_lack_is_an_error(rows):
    with pytest.raises(ValueError, match="no metric column \\['colour'\\]"):
        select(rows, colour="red")
    with pytest.raises(ValueError):
        row(True, level="L9")  # not a level: refused when the row is built, not counted as its own group
