"""The Ray executor on a real local Ray instance (`ray` comes with the dev extra)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.config import ExecutorConfig
from pipeline.executors import SetAside, make_executor
from pipeline.executors.ray import RayExecutor
from work_fns import context_kept, explode, read_env, slow_write, square, write_once

import ray  # noqa: E402,F401  (a missing ray must fail here, not skip)
from ray.cluster_utils import Cluster  # noqa: E402

HERE = Path(__file__).parent
# ray workers do not inherit sys.path: point them at this folder (work_fns) and the repo
# One xdist worker runs them all, one after another: a simulated cluster alive in one worker
# would otherwise be joined by another worker's `ray.init()`, which looks for a local cluster.
pytestmark = pytest.mark.xdist_group("ray")

WORKER_ENV = {"PYTHONPATH": f"{HERE}:{HERE.parents[1]}"}


@pytest.mark.slow
def test_ray_runs_items_relays_events_and_sets_worker_env():
    env = {"LP_NUM_THREADS": "1", **WORKER_ENV}
    ex = make_executor(ExecutorConfig(kind="ray", workers=2), worker_env=env)
    events = []
    assert ex.run(square, [1, 2, 3], events.append) == [1, 4, 9]
    assert sorted(e["item"] for e in events) == [1, 2, 3]
    assert ex.run(read_env, ["LP_NUM_THREADS"]) == ["1"]
    # an actor keeps its WorkerContext (stage 1: env, policy, render process) across items
    (pid1, builds1, uses1), (pid2, builds2, uses2) = make_executor(
        ExecutorConfig(kind="ray", workers=1), worker_env=WORKER_ENV).run(context_kept, [1, 2])
    assert pid1 == pid2 and (builds1, builds2) == (1, 1) and (uses1, uses2) == (1, 2)
    with pytest.raises(Exception, match="item 2 is broken"):
        ex.run(explode, [1, 2, 3])


@pytest.mark.slow
def test_a_crashed_ray_worker_costs_its_item_one_attempt_and_a_crash_every_time_sets_it_aside(tmp_path):
    dies = {"a": "", "b": "first", "c": "always", "d": ""}
    ex = RayExecutor(workers=2, worker_env=WORKER_ENV, max_retries=1)
    results = ex.run(write_once, [(str(tmp_path), n, d) for n, d in dies.items()], label=lambda i, it: it[1])
    assert results[:2] == ["a", "b"] and results[3] == "d"
    assert isinstance(results[2], SetAside) and results[2].attempts == 2
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a", "b", "d"]
    assert sorted(r.label for r in ex.report.retried) == ["b", "c"]
    assert all(r.reason.startswith("ActorDiedError") for r in ex.report.retried)  # its worker (an actor) died


@pytest.fixture
def cluster():
    """A head that runs no tasks and two one-CPU worker nodes, all on this machine."""
    c = Cluster(initialize_head=True, head_node_args={
        "num_cpus": 0,
        # notice a dead node in about a second instead of the default half minute
        "_system_config": {"health_check_initial_delay_ms": 0, "health_check_period_ms": 300,
                           "health_check_failure_threshold": 3},
    })
    try:
        nodes = [c.add_node(num_cpus=1, resources={name: 1}) for name in ("node_a", "node_b")]
        c.wait_for_nodes()
        yield c, nodes
    finally:
        c.shutdown()


@pytest.mark.slow
def test_losing_a_worker_node_mid_run_loses_no_item_and_duplicates_none(cluster, tmp_path):
    c, (_, doomed) = cluster
    names = [f"u{i}" for i in range(6)]
    ran_on_doomed: list[str] = []

    def on_event(ev) -> None:
        if isinstance(ev, dict) and ev["node"] == doomed.node_id:
            ran_on_doomed.append(ev["item"])
            if len(ran_on_doomed) == 1:  # its first item is in flight: pull the node
                c.remove_node(doomed)

    ex = RayExecutor(workers=2, address=c.address, worker_env=WORKER_ENV)
    out = tmp_path / "out"
    results = ex.run(slow_write, [(str(out), n, 1.0) for n in names], on_event, label=lambda i, it: it[1])
    assert results == names and not any(isinstance(r, SetAside) for r in results)
    files = sorted(p.name for p in out.iterdir() if not p.name.startswith("."))  # dot files: killed writes
    assert files == names and all((out / n).read_text() == f"{n}\n" for n in names)
    assert ran_on_doomed and ex.report.set_aside == []
    # the item in flight there is retried (others already handed to that node may be too)
    assert ran_on_doomed[0] in [r.label for r in ex.report.retried]
    assert all(r.reason.startswith(("ActorDiedError", "NodeDiedError", "WorkerCrashedError"))
               for r in ex.report.retried)
    assert "retried" in ex.report.summary()
