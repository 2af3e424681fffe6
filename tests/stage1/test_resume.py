"""Stage 1 survives a kill: SIGKILL a real run midway, rerun it, and nothing is missing or twice."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from pipeline.atomic import Completions
from pipeline.records import read_episodes

HERE = Path(__file__).parent
N_EPISODES = 16  # room for a kill between the 2nd and the last marker on a loaded machine (8 all finished once)

SCRIPT = f"""
import sys
sys.path.insert(0, {str(HERE)!r})
import toy_policy
from pipeline.config import load_config
from pipeline.stage1.run import run
if __name__ == "__main__":
    result = run(load_config(sys.argv[1]), policy_factory=toy_policy.make)
    print("RESULT", result["planned"], result["done"], result["ran"])
"""


def _config(tmp_path: Path) -> Path:
    cfg = {
        "run": {"name": "kill", "output_dir": str(tmp_path / "run"), "seed": 3},
        "tasks": {"suites": ["libero_spatial"], "max_tasks_per_suite": 1, "init_states": list(range(N_EPISODES))},
        "executor": {"kind": "local", "workers": 2},
        "stage1": {
            "policy": {"kind": "scripted", "name": "drift"},
            "rollout": {"horizon": 40, "chunk_size": 8, "settle_steps": 2},
            "video": {"cameras": ["agentview"], "fps": 5, "resolution": 64, "render": "all"},
        },
    }
    path = tmp_path / "kill.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _children(pid: int) -> list[int]:
    out = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        out += [int(p) for p in (task / "children").read_text().split()]
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.sim
@pytest.mark.slow
def test_killed_run_resumes_to_a_complete_manifest_without_duplicates(tmp_path):
    cfg = _config(tmp_path)
    stage1 = tmp_path / "run" / "stage1"
    cmd = [sys.executable, "-c", SCRIPT, str(cfg)]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = time.time() + 300
    # counted as the runner counts them: a marker being written is a dot-named temp file that
    # a `*.done` glob also matches (with the glob, a loaded fresh-clone run killed at 1 done)
    while time.time() < deadline and len(Completions(stage1).done_ids()) < 2:
        assert proc.poll() is None, proc.stdout.read().decode()[-3000:]
        time.sleep(0.05)
    workers = _children(proc.pid)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done_at_kill = len(Completions(stage1).done_ids())  # not a marker's temp file left by the kill
    assert 2 <= done_at_kill < N_EPISODES, "the kill came too late to test resumption"
    # workers die with their parent (no orphan keeps writing episodes)
    assert workers
    for _ in range(100):
        alive = [w for w in workers if _alive(w)]
        if not alive:
            break
        time.sleep(0.1)
    assert not alive, [Path(f"/proc/{w}/cmdline").read_bytes()[:200] for w in alive]
    assert not (stage1 / "episodes.parquet").exists()

    rerun = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stdout[-3000:] + rerun.stderr[-3000:]
    planned, done, ran = map(int, rerun.stdout.split("RESULT")[1].split())
    assert (planned, done) == (N_EPISODES, N_EPISODES)
    assert ran == N_EPISODES - done_at_kill  # done episodes were skipped, not redone

    records = read_episodes(stage1 / "episodes.parquet")
    keys = [r.key for r in records]
    assert len(keys) == N_EPISODES == len(set(keys))
    assert sorted(r.init_state for r in records) == list(range(N_EPISODES))
    for r in records:
        folder = stage1 / r.path
        names = sorted(p.name for p in folder.iterdir())
        assert names == ["actions.npy", "frames.parquet", "states.npy", "steps.parquet", "video_agentview.mp4"], names
        states = np.load(folder / "states.npy")
        assert states.shape == (r.steps + 1, r.state_dim)
        assert pq.read_table(folder / "steps.parquet").num_rows == r.steps
    # no episode folder beyond the planned ones (an interrupted attempt was cleaned up)
    on_disk = {str(p.relative_to(stage1)) for p in stage1.glob("episodes/*/*/*")}
    assert on_disk == {r.path for r in records}
