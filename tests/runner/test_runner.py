"""The runner on a pure-Python stage: resumption, set-aside, retry after kill -9, one event shape."""

from __future__ import annotations

import io
import json
import os
from pathlib import Path

import pytest
from rich.console import Console

from pipeline.executors.local import InlineExecutor, LocalExecutor
from pipeline.runner import Event, Runner
from tests.runner.fake_stage import make

NAMES = [f"u{i}" for i in range(5)]


def _runner(executor) -> Runner:
    return Runner(executor, console=Console(file=io.StringIO()))


def _runs(folder: Path, name: str) -> list[tuple[int, int]]:
    path = folder / "runs" / name
    return [tuple(map(int, line.split())) for line in path.read_text().splitlines()] if path.exists() else []


def test_a_rerun_skips_done_units_and_redoes_only_the_one_whose_input_changed(tmp_path):
    stage = make(tmp_path, NAMES)
    stats = _runner(LocalExecutor(workers=2)).run(stage, None)
    assert stats.ran == 5 and stats.set_aside == []
    assert json.loads((tmp_path / "_done" / "u0.done").read_text()) == {
        "chars": len("u0 input"), "inputs": f"{(tmp_path / 'in' / 'u0').stat().st_size}:"
                                            f"{(tmp_path / 'in' / 'u0').stat().st_mtime_ns}"}
    assert _runner(InlineExecutor()).run(stage, None).ran == 0  # everything done: nothing runs
    (tmp_path / "in" / "u3").write_text("u3 fixed input")
    stats = _runner(InlineExecutor()).run(stage, None)
    assert stats.ran == 1 and {n: len(_runs(tmp_path, n)) for n in NAMES} == {n: 1 + (n == "u3") for n in NAMES}
    assert (tmp_path / "out" / "u3").read_text() == "U3 FIXED INPUT"


def test_a_marker_without_recorded_inputs_counts_as_done(tmp_path):
    stage = make(tmp_path, ["a"])
    (tmp_path / "_done").mkdir()
    (tmp_path / "_done" / "a.done").write_text("{}\n")  # written before fingerprints existed
    assert _runner(InlineExecutor()).run(stage, None).ran == 0


def test_a_failing_unit_is_set_aside_with_its_reason_the_rest_go_on_and_a_fixed_one_is_picked_up(tmp_path):
    stage = make(tmp_path, NAMES, {"u1": "fail"})
    stats = _runner(LocalExecutor(workers=2)).run(stage, None)
    assert stats.ran == 4
    [aside] = stats.set_aside
    assert (aside.unit, aside.reason, aside.detail) == ("u1", "ValueError", "u1 is broken")
    assert not (tmp_path / "_done" / "u1.done").exists()  # no marker: the rerun tries it again
    assert (tmp_path / "aside" / "u1.txt").read_text() == "ValueError: u1 is broken\n"
    stage.modes.clear()
    assert _runner(LocalExecutor(workers=2)).run(stage, None).ran == 1
    assert not (tmp_path / "aside" / "u1.txt").exists()  # its marker clears the old set-aside record


def test_a_unit_whose_worker_is_killed_runs_again_and_one_killed_every_time_is_set_aside(tmp_path):
    stage = make(tmp_path, NAMES, {"u1": "die", "u3": "always"})
    events: list[Event] = []
    stats = _runner(LocalExecutor(workers=2, max_retries=1)).run(stage, None, on_event=events.append)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["u0", "u1", "u2", "u4"]
    assert len(_runs(tmp_path, "u1")) == 2 and len(_runs(tmp_path, "u3")) == 2
    assert sorted(e.unit for e in stats.retried) == ["u1", "u3"]
    assert all("SIGKILL" in e.reason for e in stats.retried)
    [aside] = stats.set_aside
    assert (aside.unit, aside.reason) == ("u3", "WorkerDied") and "SIGKILL" in aside.detail
    assert stats.ran == 4 and stats.report.set_aside[0].label == "u3"


def test_a_worker_keeps_its_context_across_units_and_closes_it_when_the_run_ends(tmp_path):
    stage = make(tmp_path, NAMES)
    _runner(LocalExecutor(workers=1)).run(stage, None)
    runs = [_runs(tmp_path, n)[0] for n in NAMES]
    assert len({pid for pid, _ in runs}) == 1 and sorted(n for _, n in runs) == [1, 2, 3, 4, 5]
    assert os.getpid() not in {pid for pid, _ in runs}
    [closed] = (tmp_path / "closed").iterdir()  # the worker closed its context on a clean stop
    assert int(closed.name) == runs[0][0] and closed.read_text() == "5\n"


def _shape(events: list) -> list[tuple]:
    return sorted((type(e).__name__, e.kind, e.stage, e.unit, e.ok, e.reason) for e in events)


@pytest.mark.slow
@pytest.mark.xdist_group("ray")
def test_local_and_ray_executors_emit_the_same_events(tmp_path):
    from pipeline.executors.ray import RayExecutor

    shapes = []
    root = Path(__file__).parents[2]
    for name, ex in [("local", LocalExecutor(workers=2)), ("inline", InlineExecutor()),
                     ("ray", RayExecutor(workers=2, worker_env={"PYTHONPATH": str(root)}))]:
        stage = make(tmp_path / name, NAMES, {"u2": "fail"})
        events: list[Event] = []
        _runner(ex).run(stage, None, on_event=events.append)
        assert all(isinstance(e, Event) for e in events)
        shapes.append(_shape(events))
        # every kind of worker (process, this process, Ray actor) keeps its context across units
        assert max(n for u in NAMES for _, n in _runs(tmp_path / name, u)) >= 3
    assert shapes[0] == shapes[1] == shapes[2]
    assert [k for _, k, *_ in shapes[0]].count("set_aside") == 1 and len(shapes[0]) == 10  # started + outcome


def test_a_retryable_error_is_retried_with_backoff_and_set_aside_after_the_last_try(tmp_path):
    """The taxonomy's RetryableError: a flaky unit succeeds on its second try; a unit that stays
    busy is tried `tries` times, each lost try a `retry` event with its wait, then set aside."""
    from pipeline.config import ExecutorConfig, RetryConfig
    from pipeline.executors import make_executor

    stage = make(tmp_path, NAMES, {"u1": "flaky", "u3": "busy"})
    cfg = ExecutorConfig(workers=2, retry=RetryConfig(tries=3, backoff_s=0.2, max_backoff_s=0.3))
    events: list[Event] = []
    stats = _runner(make_executor(cfg)).run(stage, None, on_event=events.append)
    assert stats.ran == 4 and (tmp_path / "out" / "u1").read_text() == "U1 INPUT"
    assert len(_runs(tmp_path, "u1")) == 2 and len(_runs(tmp_path, "u3")) == 3
    retries = sorted((e.unit, e.attempt, e.detail) for e in stats.retried)
    assert retries == [("u1", 1, "next try in 0.2 s"), ("u3", 1, "next try in 0.2 s"), ("u3", 2, "next try in 0.3 s")]
    assert all(e.stage == "fake" and e.reason == f"RetryableError: {e.unit}: server busy (503)" for e in stats.retried)
    [aside] = stats.set_aside
    assert (aside.unit, aside.reason) == ("u3", "RetryableError")
    assert not (tmp_path / "_done" / "u3.done").exists() and (tmp_path / "aside" / "u3.txt").exists()
    assert [e.kind for e in events if e.unit == "u1"] == ["started", "retry", "done"]
