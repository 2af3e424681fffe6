"""The local process-pool executor with real spawned workers."""

from __future__ import annotations

import os

import pytest

from pipeline.config import ExecutorConfig
from pipeline.executors import make_executor
from pipeline.executors.local import InlineExecutor, LocalExecutor
from work_fns import explode, read_env, square


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


def test_inline_executor_runs_in_this_process():
    events = []
    assert InlineExecutor().run(square, [3], events.append) == [9]
    assert events[0]["pid"] == os.getpid()


def test_config_picks_the_executor():
    assert isinstance(make_executor(ExecutorConfig(kind="local", workers=3)), LocalExecutor)
    assert make_executor(ExecutorConfig(kind="local", workers=3)).workers == 3
