"""Agreement of VLM and simulator-state onsets."""

from __future__ import annotations

import pytest

from pipeline.labelers.vlm.agreement import agreement


def test_agreement_reports_mae_and_shares_within_tolerances():
    a = agreement([(2.0, 2.0), (3.0, 2.5), (5.0, 4.0), (10.0, 7.0)])
    assert a.n == 4
    assert a.mae_s == pytest.approx((0 + 0.5 + 1.0 + 3.0) / 4)
    assert a.within_0_5s == pytest.approx(0.5)  # 0 and exactly 0.5 count
    assert a.within_1s == pytest.approx(0.75)


def test_boundary_differences_count_despite_float_error():
    assert agreement([(0.3, 0.8)]).within_0_5s == 1.0  # 0.8 - 0.3 = 0.5000000000000001


def test_no_pairs_gives_no_statistics():
    a = agreement([])
    assert a.n == 0 and a.mae_s is None and a.within_1s is None


def test_non_finite_time_is_refused():
    with pytest.raises(ValueError, match="non-finite"):
        agreement([(float("nan"), 1.0)])
