"""Session fixtures for stage 2: real LIBERO episodes (tests/stage2/rollouts.py), their
evidence, and one full stage-2 run over them. Built once, shared by every stage-2 test."""

from __future__ import annotations

import fcntl
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.stage2.rollouts import PLANS, SUITE, TASK, make_fixture_run


@pytest.fixture(scope="session")
def stage1_run(request) -> Path:
    cache = Path(request.config.cache.mkdir("stage2-rollouts"))
    with open(cache / ".lock", "w") as lock:  # xdist workers: build once, the others wait
        fcntl.flock(lock, fcntl.LOCK_EX)
        return make_fixture_run(cache)


@pytest.fixture(scope="session")
def spatial_env():
    from pipeline.sim import build_env, get_task

    env = build_env(get_task(SUITE, TASK))
    yield env
    env.close()


@pytest.fixture(scope="session")
def episodes(stage1_run):
    from pipeline.records import read_episodes

    return {r.policy.removeprefix("fixture_"): r for r in read_episodes(stage1_run / "stage1" / "episodes.parquet")}


@pytest.fixture(scope="session")
def evidences(stage1_run, spatial_env, episodes):
    """plan name -> Evidence computed from the logged states."""
    from pipeline.evidence import compute_evidence
    from pipeline.stage2.layout import load_episode

    out = {}
    for name in PLANS:
        ep = load_episode(stage1_run / "stage1", episodes[name])
        out[name] = compute_evidence(spatial_env, ep.states, np.asarray(ep.steps["action"])[:, 6])
    return out


@pytest.fixture(scope="session")
def stage2_run(stage1_run, tmp_path_factory) -> Path:
    """A run folder after `pipeline.stage2.run.run` (simstate, one local worker)."""
    from pipeline.config import Config
    from pipeline.stage2.run import run

    root = tmp_path_factory.getbasetemp() / "stage2_run"
    if not (root / "stage2" / "summary.json").exists():
        shutil.rmtree(root, ignore_errors=True)
        shutil.copytree(stage1_run, root)
        run(Config.model_validate({"run": {"output_dir": str(root)}, "executor": {"workers": 1}}))
    return root
