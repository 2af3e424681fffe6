"""The local process-pool executor with real spawned workers."""

from __future__ import annotations

import os

import pytest

from pipeline.config import ExecutorConfig
from pipeline.executors import SetAside, make_executor
from pipeline.executors.local import InlineExecutor, LocalExecutor
from pipeline.runner import Event
from work_fns import counted, explode, read_env, square, write_once


def test_results_come_back_in_item_order_and_events_reach_the_caller():
    events = []
    results = LocalExecutor(workers=2).run(square, list(range(6)), events.append)
    assert results == [0, 1, 4, 9, 16, 25]
    assert sorted(e["item"] for e in events) == list(range(6))
    assert os.getpid() not in {e["pid"] for e in events}  # the work ran in other processes


def test_worker_environment_is_set_before_the_work_runs():
    ex = LocalExecutor(workers=1, worker_env={"LP_NUM_THREADS": "1"})
    assert ex.run(read_env, ["LP_NUM_THREADS"]) == ["1"]


def test_an_exception_in_a_worker_stops_the_run_and_reaches_the_caller():
    with pytest.raises(ValueError, match="item 2 is broken"):
        LocalExecutor(workers=2).run(explode, [1, 2, 3])


def test_a_worker_keeps_its_module_state_across_items():
    results = LocalExecutor(workers=1).run(counted, list(range(4)))
    assert len({pid for pid, _ in results}) == 1
    assert [n for _, n in results] == [1, 2, 3, 4]  # what a cached environment relies on


def _attempts(tmp_path, name: str) -> int:
    return len((tmp_path / "attempts" / name).read_text().splitlines())


def test_a_worker_killed_under_an_item_costs_only_that_item_one_attempt(tmp_path):
    names = [f"u{i}" for i in range(6)]
    modes = {"u0": "wait:u1", "u1": "first"}  # u0 is in flight in the other worker when u1's dies
    items = [(str(tmp_path), n, modes.get(n, "")) for n in names]
    events = []
    ex = LocalExecutor(workers=2)
    assert ex.run(write_once, items, events.append, label=lambda i, it: it[1]) == names
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == names
    assert {n: _attempts(tmp_path, n) for n in names} == {n: 2 if n == "u1" else 1 for n in names}
    # the other worker was not torn down with the dead one: 2 workers + 1 replacement in all
    assert len({e["pid"] for e in events if isinstance(e, dict)}) == 3
    [retry_ev] = [e for e in events if isinstance(e, Event)]  # the executor's own: one lost attempt
    assert (retry_ev.kind, retry_ev.unit, retry_ev.attempt) == ("retry", "u1", 1)
    [retry] = ex.report.retried
    assert (retry.label, retry.attempt) == ("u1", 1) and "SIGKILL" in retry.reason
    assert ex.report.set_aside == [] and "retried u1" in ex.report.summary()


def test_an_item_whose_worker_always_dies_is_set_aside_after_the_bound(tmp_path):
    names = ["a", "b", "c", "d"]
    items = [(str(tmp_path), n, "always" if n == "b" else "") for n in names]
    ex = LocalExecutor(workers=2, max_retries=1)
    results = ex.run(write_once, items)
    assert [r for r in results if not isinstance(r, SetAside)] == ["a", "c", "d"]
    aside = results[1]
    assert isinstance(aside, SetAside) and aside.attempts == 2 and "SIGKILL" in aside.reason
    assert ex.report.set_aside == [aside] and len(ex.report.retried) == 1
    assert _attempts(tmp_path, "b") == 2
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a", "c", "d"]
    assert "set aside item 1 after 2 attempt(s)" in ex.report.summary()


def test_inline_executor_runs_in_this_process():
    events = []
    assert InlineExecutor().run(square, [3], events.append) == [9]
    assert events[0]["pid"] == os.getpid()


def test_config_picks_the_executor():
    assert isinstance(make_executor(ExecutorConfig(kind="local", workers=3)), LocalExecutor)
    assert isinstance(make_executor(ExecutorConfig(kind="inline")), InlineExecutor)
    assert make_executor(ExecutorConfig(kind="local", workers=3)).workers == 3
    assert make_executor(ExecutorConfig(kind="local", max_retries=5)).max_retries == 5
