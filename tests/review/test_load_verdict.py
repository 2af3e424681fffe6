"""benchmarks/review_load.py exits non-zero when an aim is missed."""

from __future__ import annotations

from benchmarks.review_load import missed


def _res(**kw) -> dict:
    return {"reviewers": 20, "decision_p95_ms": 80.0, "lost_decisions": 0, "items_over_k": 0, "refused": 0,
            "errors": [], **kw}


def test_a_run_within_every_aim_misses_nothing():
    assert missed(_res(reviewers=1), _res(), 100) == []


def test_a_slow_lossy_or_over_k_run_misses_its_aims():
    assert missed(_res(reviewers=1), _res(decision_p95_ms=235.0), 100) == ["decision p95 235.0 ms > 100 ms"]
    assert missed(_res(reviewers=1), _res(decision_p95_ms=float("nan")), 100)  # no decisions at all
    got = missed(_res(reviewers=1, lost_decisions=1), _res(items_over_k=2), 100)
    assert got == ["1 decision(s) lost (1 reviewer)", "2 item(s) over K (20 reviewers)"]
