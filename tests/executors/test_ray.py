"""The Ray executor on a real local Ray instance (`ray` comes with the dev extra)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.config import ExecutorConfig
from pipeline.executors import make_executor
from work_fns import explode, read_env, square

import ray  # noqa: E402,F401  (a missing ray must fail here, not skip)


@pytest.mark.slow
def test_ray_runs_items_relays_events_and_sets_worker_env():
    # ray workers do not inherit sys.path: point them at this folder (work_fns) and the repo
    here = Path(__file__).parent
    env = {"LP_NUM_THREADS": "1", "PYTHONPATH": f"{here}:{here.parents[1]}"}
    ex = make_executor(ExecutorConfig(kind="ray", workers=2), worker_env=env)
    events = []
    assert ex.run(square, [1, 2, 3], events.append) == [1, 4, 9]
    assert sorted(e["item"] for e in events) == [1, 2, 3]
    assert ex.run(read_env, ["LP_NUM_THREADS"]) == ["1"]
    with pytest.raises(Exception, match="item 2 is broken"):
        ex.run(explode, [1, 2, 3])
