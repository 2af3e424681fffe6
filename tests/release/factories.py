"""Fixture factories for release tests: a tiny but real run folder on one LIBERO task.

`scene_source` builds the task's environment once per session and records a short real
episode (the robot raises its arm, objects settle): its states, step log and final state
are real simulator output. `make_run` lays out stage 1/2/3 outputs as the pipeline writes
them (episodes.parquet, Localization JSON, scene pair + history, final annotation JSON) for
any number of episodes, each with its own (possibly corrupted) scene state and BDDL text.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from pipeline.atomic import write_bytes, write_json, write_with
from pipeline.records import Annotation, EpisodeRecord, Localization, Phases, episodes_table
from pipeline.rollout import StepInfo
from pipeline.stage1.recorder import EpisodeRecorder

SUITE = "libero_spatial"
TASK_INDEX = 0


@dataclass
class SceneSource:
    task: object  # TaskSpec
    bddl_text: str
    states: np.ndarray  # (steps+1, dim) of the recorded episode
    steps_table: object  # pyarrow table (STEP_SCHEMA)
    actions: np.ndarray  # (steps, 7) float64, as stepped (actions.npy)
    failure: np.ndarray  # a settled state with the goal not satisfied
    satisfied: np.ndarray  # a settled state with the goal satisfied


def _episode(env) -> EpisodeRecorder:
    env.reset_to_init(0)
    env.settle(10)
    rec = EpisodeRecorder(env)
    actions = [np.array([0, 0, 0.6, 0, 0, 0, -1.0])] * 8 + [np.array([0, 0, 0, 0, 0, 0, -1.0])] * 16
    for i, a in enumerate(actions):
        goal = env.step(a)
        rec.on_step(StepInfo(step=i, action=a, query=i % 8 == 0, goal=goal))
    return rec


def _goal_state(env, start: np.ndarray) -> np.ndarray:
    """Put the target bowl on the plate and let it settle: a state where the goal holds."""
    env.reset_to(start)
    obj, target = env.goal[0][1], env.goal[0][2]
    adr = env.free_joints()[obj]
    plate, _ = env.object_pose(target)
    s = env.get_state()
    s[1 + adr : 1 + adr + 3] = plate + np.array([0.0, 0.0, 0.04])
    s[1 + env.env.sim.model.nq :] = 0.0
    env.set_state(s)
    env.settle(40)
    assert env.goal_satisfied(), "fixture: could not build a goal-satisfied state"
    return env.get_state()


@pytest.fixture(scope="session")
def scene_source() -> SceneSource:
    from pipeline.sim import SimEnv, tasks

    task = tasks([SUITE])[TASK_INDEX]
    with SimEnv(task) as env:
        rec = _episode(env)
        states = rec.states_array()
        assert not env.goal_satisfied()
        satisfied = _goal_state(env, states[-1])
    # the official BDDL files already declare each type's objects on one line (normalized)
    return SceneSource(task, task.bddl_path.read_text(), states, rec.table(), rec.actions_array(), states[-1], satisfied)


def annotation(suite: str, task: str, ep_id: str, instruction: str, fail_step: int) -> dict:
    """A final annotation as the review export writes it (`records.Annotation`)."""
    review = {"decision": "accept", "recovery_level": "L2", "at": "2025-01-01T00:00:00Z"}
    return Annotation(
        key=f"{suite}/{task}/{ep_id}", suite=suite, task=task, episode_id=ep_id, revision=1,
        instruction=instruction, fail_time_s=fail_step / 20, fail_step=fail_step, recovery_level="L2",
        failure_category="grasp_failure", recovery_action="Re-grasp the bowl and place it on the plate",
        resolution="agreed", model_proposal={"recovery_level": "L1", "characterizer": {"prompt_hash": "c0ffee01"}},
        reviews=[{"reviewer": "alice", **review}, {"reviewer": "bob", **review}], finalized_at="2025-01-01T00:00:00Z",
    ).model_dump(mode="json")


def make_run(root: Path, src: SceneSource, scenes: dict[str, tuple[bytes, str]], policy: str = "scripted",
             policy_params: dict | None = None) -> Path:
    """A run folder with one failed episode per entry: episode id -> (npy bytes, BDDL text),
    all by one generator (`policy`, `policy_params`)."""
    import pyarrow.parquet as pq

    t = src.task
    step = len(src.states) - 1
    records = []
    for i, (ep_id, (npy, bddl)) in enumerate(sorted(scenes.items())):
        ep_dir = Path(t.suite) / t.name / ep_id
        folder = root / "stage1" / "episodes" / ep_dir
        write_with(folder / "states.npy", lambda p: np.save(p, src.states))
        write_with(folder / "steps.parquet", lambda p: pq.write_table(src.steps_table, p))
        write_with(folder / "actions.npy", lambda p: np.save(p, src.actions))
        records.append(EpisodeRecord(
            suite=t.suite, task=t.name, task_index=t.index, instruction=t.instruction, episode_id=ep_id,
            init_state=0, policy=policy, policy_kind="scripted", policy_params=policy_params or {}, seed=i, chunk_size=8, horizon=24,
            settle_steps=10, steps=step, success=False, wall_time_s=1.0, state_dim=src.states.shape[1],
            path=f"episodes/{ep_dir.as_posix()}"))
        scene = Path(f"selected_bddl_scenes_{t.suite}") / t.name / f"episode_{ep_id}"
        write_bytes(root / "stage2" / scene / f"step_{step:04d}.bddl", bddl.encode())
        write_bytes(root / "stage2" / scene / f"step_{step:04d}_sim_state.npy", npy)
        write_with(root / "stage2" / scene / f"step_{step:04d}_history.npy", lambda p: np.save(p, src.states[:-1]))
        key = f"{t.suite}/{t.name}/{ep_id}"
        loc = Localization(
            key=key, suite=t.suite, task=t.name, episode_id=ep_id, instruction=t.instruction, source="simstate",
            prompt_hash=None, fail_time_s=(step - 4) / 20, fail_step=step - 4,
            phases=Phases(pre=(0, step - 4), during=(step - 4, step), post=(step, step + 1)),
            scene_bddl=f"{scene.as_posix()}/step_{step:04d}.bddl",
            scene_state=f"{scene.as_posix()}/step_{step:04d}_sim_state.npy",
            history=f"{scene.as_posix()}/step_{step:04d}_history.npy")
        write_bytes(root / "stage2" / "localizations" / t.suite / t.name / f"{ep_id}.json",
                    loc.model_dump_json(indent=2).encode())
        write_json(root / "stage3" / "annotations" / t.suite / t.name / f"episode_{ep_id}.json",
                   annotation(t.suite, t.name, ep_id, t.instruction, step - 4))
    table = episodes_table(records)
    write_with(root / "stage1" / "episodes.parquet", lambda p: pq.write_table(table, p))
    return root


def npy_bytes(arr: np.ndarray) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def release_config(run: Path, executor: str = "local", **release):
    from pipeline.config import Config

    return Config.model_validate({
        "run": {"output_dir": str(run)},
        "executor": {"kind": executor},
        "tasks": {"suites": [SUITE], "max_tasks_per_suite": 1, "init_states": [0]},
        "release": {"certify_tries": 0, **release},
    })
