"""benchmarks/review_load.py exits non-zero when an aim is missed."""

from __future__ import annotations

from benchmarks.review_load import missed


def _res(**kw) -> dict:
    return {"decision_p95_ms": 80.0, "item_page_p95_ms": 120.0, "lost_decisions": 0, "items_over_k": 0,
            "refused": 0, "errors": [], **kw}


def test_a_run_within_every_aim_misses_nothing():
    assert missed("sqlite-1", _res()) == []


def test_a_slow_lossy_or_over_k_run_misses_its_aims():
    assert missed("sqlite-1", _res(decision_p95_ms=235.0)) == ["sqlite-1: decision_p95 235.0 ms > 100 ms"]
    assert missed("sqlite-1", _res(item_page_p95_ms=151.0)) == ["sqlite-1: item_page_p95 151.0 ms > 150 ms"]
    assert missed("pg", _res(decision_p95_ms=float("nan")))  # no decisions at all
    assert missed("pg", _res(lost_decisions=1, items_over_k=2)) == ["pg: 1 decision(s) lost", "pg: 2 item(s) over K"]
