"""Agreement statistics against values computed by hand (and published reference values)."""

from __future__ import annotations

import math

import pytest

from pipeline.review.stats import cohen_kappa, confusion, fleiss_kappa, krippendorff_alpha, within_tolerance


def test_cohen_kappa_matches_a_hand_computation():
    # po = 3/4; pe = (2*1 + 2*3)/16 = 1/2 -> kappa = (0.75 - 0.5) / 0.5
    assert cohen_kappa(["A", "A", "B", "B"], ["A", "B", "B", "B"]) == pytest.approx(0.5)


def test_cohen_kappa_is_one_for_perfect_agreement_and_undefined_without_variation():
    assert cohen_kappa(["L1", "L2", "L3"], ["L1", "L2", "L3"]) == pytest.approx(1.0)
    assert math.isnan(cohen_kappa(["L1", "L1"], ["L1", "L1"]))


def test_fleiss_kappa_matches_the_classic_14_rater_example():
    # Fleiss (1971)-style table as used in most textbooks: kappa = 0.210
    table = [[0, 0, 0, 0, 14], [0, 2, 6, 4, 2], [0, 0, 3, 5, 6], [0, 3, 9, 2, 0], [2, 2, 8, 1, 1],
             [7, 7, 0, 0, 0], [3, 2, 6, 3, 0], [2, 5, 3, 2, 2], [6, 5, 2, 1, 0], [0, 2, 2, 3, 7]]
    assert fleiss_kappa(table) == pytest.approx(0.2099, abs=1e-4)


def test_fleiss_kappa_with_two_raters_equals_its_own_hand_computation():
    # items: (A,A) (A,B) (B,B): P_i = 1, 0, 1 -> P = 2/3; p_A = p_B = 1/2 -> Pe = 1/2 -> kappa = 1/3
    assert fleiss_kappa([[2, 0], [1, 1], [0, 2]]) == pytest.approx(1 / 3)


def test_krippendorff_nominal_alpha_matches_a_hand_computation():
    # coincidences o_aa = 2, o_ab = o_ba = 1, o_bb = 2; n_a = n_b = 3, n = 6
    # alpha = 1 - (n-1) * sum(o*d) / sum(n_c n_k d) = 1 - 5 * 2 / 18 = 4/9
    assert krippendorff_alpha([["a", "a"], ["a", "b"], ["b", "b"]], "nominal") == pytest.approx(4 / 9)


def test_krippendorff_alpha_matches_the_published_reliability_example():
    # Krippendorff (2011), "Computing Krippendorff's alpha-reliability": 4 coders, 12 units, gaps
    a = [1, 2, 3, 3, 2, 1, 4, 1, 2, None, None, None]
    b = [1, 2, 3, 3, 2, 2, 4, 1, 2, 5, None, 3]
    c = [None, 3, 3, 3, 2, 3, 4, 2, 2, 5, 1, None]
    d = [1, 2, 3, 3, 2, 4, 4, 1, 2, 5, 1, None]
    units = [list(u) for u in zip(a, b, c, d)]
    assert krippendorff_alpha(units, "nominal") == pytest.approx(0.743, abs=1e-3)
    assert krippendorff_alpha(units, "ordinal", order=[1, 2, 3, 4, 5]) == pytest.approx(0.815, abs=1e-3)
    assert krippendorff_alpha(units, "interval") == pytest.approx(0.849, abs=1e-3)


def test_ordinal_alpha_punishes_distant_levels_more_than_nominal():
    order = ["L1", "L2", "L3", "L4"]
    near = [["L1", "L1"], ["L2", "L2"], ["L3", "L4"], ["L4", "L4"], ["L2", "L1"]]
    far = [["L1", "L1"], ["L2", "L2"], ["L3", "L3"], ["L4", "L1"], ["L1", "L4"]]
    assert krippendorff_alpha(near, "ordinal", order) > krippendorff_alpha(near, "nominal")
    assert krippendorff_alpha(far, "ordinal", order) < krippendorff_alpha(far, "nominal")


def test_timestamp_agreement_counts_items_whose_times_all_lie_within_tau():
    assert within_tolerance([[1.0, 1.4], [2.0, 2.6], [3.0, 3.1, 3.5], [9.0]], 0.5) == pytest.approx(2 / 3)


def test_confusion_rows_are_final_and_columns_are_model():
    m = confusion([("L1", "L2"), ("L1", "L1"), ("L3", "L3")], ["L1", "L2", "L3"])
    assert m == [[1, 1, 0], [0, 0, 0], [0, 0, 1]]
