"""Fixture factories for evaluation tests: tiny real scenes made on the real simulator.

`fixture_run` holds, for libero_spatial task 0, a stage-1 style episode folder (states.npy +
steps.parquet, recorded by stage 1's own recorder from init state 0 under a short scripted
motion) and a scene cut from it at step 40 in the release layout
(`selected_bddl_scenes_<suite>/<task>/episode_<id>/step_0040.bddl` + `_sim_state.npy`).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

SCENE_STEP = 40
EPISODE_ID = "fixture-i00-s0"


def motion() -> np.ndarray:
    """A rollout that keeps clear of the objects: still, move, rest (to step 40), close, lift."""
    a = np.zeros((80, 7))
    a[:, 6] = -1.0
    a[10:30, 0] = 0.3
    a[10:30, 2] = -0.2
    a[50:, 6] = 1.0
    a[60:70, 2] = 0.3
    return a


class HoldPolicy:
    """A tiny state-only policy: holds the arm still with a fixed gripper command."""

    cameras: tuple[str, ...] = ()
    image_size = 64

    def __init__(self, name: str = "hold", gripper: float = -1.0, chunk: int = 8):
        self.name, self.gripper, self.chunk = name, gripper, chunk
        self.seeds: list[int] = []
        self.contexts: list[dict] = []
        self.closed = False

    def reset(self, task, seed: int) -> None:
        self.seeds.append(seed)

    def act(self, obs) -> np.ndarray:
        self.contexts.append(obs.context)
        out = np.zeros((self.chunk, 7))
        out[:, 6] = self.gripper
        return out

    def params(self) -> dict:
        return {"gripper": self.gripper}

    def close(self) -> None:
        self.closed = True


@dataclass(frozen=True)
class FixtureRun:
    root: Path
    stage1: Path  # holds episodes/<suite>/<task>/<episode_id>/
    scenes: Path  # release-layout scene folder
    episode: Path
    bddl: Path
    state: Path
    suite: str
    task: str


@pytest.fixture(scope="session")
def fixture_run(tmp_path_factory) -> FixtureRun:
    from pipeline.rollout import run_episode
    from pipeline.sim import SimEnv, tasks
    from pipeline.stage1.recorder import EpisodeRecorder

    task = tasks(["libero_spatial"])[0]
    root = tmp_path_factory.mktemp("evalrun")
    episode = root / "stage1" / "episodes" / task.suite / task.name / EPISODE_ID
    actions = motion()

    class Replay(HoldPolicy):
        def act(self, obs):
            return actions[obs.step : obs.step + 1]

    with SimEnv(task) as env:
        env.reset_to_init(0)
        rec = EpisodeRecorder(env)
        run_episode(env, Replay(), horizon=len(actions), chunk_size=4, stop_on_success=False, on_step=rec.on_step)
        rec.write(episode)
        states = rec.states_array()
    folder = root / "scenes" / f"selected_bddl_scenes_{task.suite}" / task.name / f"episode_{EPISODE_ID}"
    folder.mkdir(parents=True)
    bddl = folder / f"step_{SCENE_STEP:04d}.bddl"
    shutil.copy(task.bddl_path, bddl)
    state = folder / f"step_{SCENE_STEP:04d}_sim_state.npy"
    np.save(state, states[SCENE_STEP])
    return FixtureRun(root, root / "stage1", root / "scenes", episode, bddl, state, task.suite, task.name)


@pytest.fixture(scope="session")
def scene_env(fixture_run):
    """One environment built from the fixture scene's own BDDL, shared by the sim tests."""
    from pipeline.eval.scenes import scene_task
    from pipeline.eval.scenes import find_scenes
    from pipeline.sim import SimEnv

    scenes, _ = find_scenes(fixture_run.scenes)
    with SimEnv(scene_task(scenes[0])) as env:
        yield env
