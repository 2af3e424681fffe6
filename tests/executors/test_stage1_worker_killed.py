"""A real stage-1 worker killed with SIGKILL from outside mid-run: the run ends complete."""

from __future__ import annotations

import io
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

import pytest
from rich.console import Console

from pipeline.config import Config
from pipeline.records import read_episodes
from pipeline.stage1.run import run

sys.path.insert(0, str(Path(__file__).parents[1] / "stage1"))
import toy_policy  # noqa: E402

N_EPISODES = 6


def _workers() -> list[int]:
    """This process's spawned pool workers (not multiprocessing's resource tracker)."""
    out = []
    for task in Path(f"/proc/{os.getpid()}/task").iterdir():
        for pid in (task / "children").read_text().split():
            try:
                if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():
                    out.append(int(pid))
            except FileNotFoundError:
                pass
    return out


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
    killed: list[int] = []

    def kill_one_after_the_first_episode() -> None:
        deadline = time.time() + 300
        while time.time() < deadline and not list(done_dir.glob("*.done")):
            time.sleep(0.05)
        # two shards of three: both workers are inside their shard now
        pid = _workers()[0]
        os.kill(pid, signal.SIGKILL)
        killed.append(pid)

    killer = threading.Thread(target=kill_one_after_the_first_episode, daemon=True)
    killer.start()
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
