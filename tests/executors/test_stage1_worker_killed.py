"""A real stage-1 worker killed with SIGKILL from outside mid-run: the run ends complete."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import pytest
from rich.console import Console

from pipeline.config import Config
from pipeline.records import read_episodes
from pipeline.stage1.run import run

sys.path.insert(0, str(Path(__file__).parents[1] / "stage1"))
import toy_policy  # noqa: E402
from killer import kill_a_worker_after_the_first_episode  # noqa: E402

N_EPISODES = 6


@pytest.mark.sim
@pytest.mark.slow
def test_a_stage1_worker_killed_mid_episode_costs_no_episode(tmp_path):
    cfg = Config.model_validate({
        "run": {"name": "kill9", "output_dir": str(tmp_path / "run"), "seed": 3},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": list(range(N_EPISODES))},
        "executor": {"kind": "local", "workers": 2},
        "stage1": {"policy": {"kind": "scripted", "name": "drift"},
                   "rollout": {"horizon": 40, "chunk_size": 8, "settle_steps": 2},
                   "video": {"render": "none"}},
    })
    done_dir = tmp_path / "run" / "stage1" / "_done"
    killer, killed = kill_a_worker_after_the_first_episode(done_dir)
    result = run(cfg, policy_factory=toy_policy.make, console=Console(file=io.StringIO()))
    killer.join()
    assert killed
    assert (result["planned"], result["done"], result["errors"]) == (N_EPISODES, N_EPISODES, [])
    stage1 = tmp_path / "run" / "stage1"
    records = read_episodes(stage1 / "episodes.parquet")
    assert sorted(r.init_state for r in records) == list(range(N_EPISODES))
    assert len({r.key for r in records}) == N_EPISODES
    report = json.loads((stage1 / "summary.json").read_text())["executor"]
    [retry] = report["retried"]
    assert f"pid {killed[0]} killed by SIGKILL" in retry["reason"] and report["set_aside"] == []
