"""One stage 1 episode: run, record and (maybe) render it (the Stage is stage.py).

Inputs: an environment, a policy, an `EpisodeUnit` and the run's `Config`.
Outputs per episode, in `stage1/<episode folder>/`: `states.npy`, `steps.parquet`, videos
and `frames.parquet` when rendered, `truth.parquet` when the policy keeps a truth log
(the scripted generator: `pipeline.policies.scripted.truth`); then the done marker
`stage1/_done/<unit_id>.done` holding the EpisodeRecord (JSON), written by the runner. The
videos are drawn by the worker's render process (render_pool.py, see stage.py) while the
physics of the next episodes runs.

Invariants: an episode is `reset_to_init(i)`, `settle(settle_steps)` (zero actions, gripper
open), `policy.reset(task, seed)`, then `run_episode`; the done marker is written last,
after every output (videos included: an episode waiting for its videos has no marker),
so a killed episode is redone (from an emptied folder) on rerun and a
done one is never redone.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from pipeline.atomic import write_with
from pipeline.config import Config, PolicyConfig
from pipeline.policies.base import Policy
from pipeline.records import EpisodeRecord
from pipeline.rollout import run_episode
from pipeline.sim import SimEnv
from pipeline.stage1.recorder import EpisodeRecorder
from pipeline.stage1.units import EpisodeUnit
from pipeline.stage1.video import render_videos

PolicyFactory = Callable[[PolicyConfig], Policy]


def should_render(mode: str, success: bool) -> bool:
    return mode == "all" or (mode == "failures" and not success)


def run_physics(env: SimEnv, policy: Policy, unit: EpisodeUnit, cfg: Config,
                stage1_dir: Path) -> tuple[EpisodeRecord, np.ndarray | None]:
    """Run and record one episode; write its states and step log. Returns its record
    (without videos) and, if it needs videos, its states (render them, then fill `videos`)."""
    r, v = cfg.stage1.rollout, cfg.stage1.video
    folder = Stage1Layout(stage1_dir).episode_dir(unit.key)
    if folder.exists():  # leftovers of an attempt killed before its marker
        shutil.rmtree(folder)
    t0 = time.perf_counter()
    env.reset_to_init(unit.init_state)
    env.settle(r.settle_steps)
    policy.reset(env.task, unit.seed)
    rec = EpisodeRecorder(env)
    watch = getattr(policy, "on_step", None)  # the scripted generator's truth log

    def on_step(info) -> None:
        rec.on_step(info)
        if watch is not None:
            watch(info.step, info.action)

    result = run_episode(env, policy, r.horizon, r.chunk_size, r.stop_on_success, on_step=on_step)
    wall = time.perf_counter() - t0
    rec.write(folder)
    truth = policy.truth_table() if hasattr(policy, "truth_table") else None
    if truth is not None:
        write_with(EpisodeFiles(Path(folder)).truth, lambda p: pq.write_table(truth, p))
    record = EpisodeRecord(
        suite=unit.suite,
        task=unit.task,
        task_index=unit.task_index,
        instruction=env.task.instruction,
        episode_id=unit.episode_id,
        init_state=unit.init_state,
        policy=unit.policy,
        policy_kind=cfg.stage1.policy.kind,
        policy_params=policy.params(),
        seed=unit.seed,
        chunk_size=r.chunk_size,
        horizon=r.horizon,
        control_hz=r.control_hz,
        settle_steps=r.settle_steps,
        steps=result.steps,
        success=result.success,
        first_success_step=result.first_success_step,
        wall_time_s=round(wall, 4),
        state_dim=env.state_dim,
        path=unit.rel_dir,
    )
    return record, rec.states_array() if should_render(v.render, result.success) else None


def with_videos(record: EpisodeRecord, videos: dict[str, str], fps: int) -> EpisodeRecord:
    return record.model_copy(update={"videos": videos, "video_fps": fps if videos else None})


def run_one(env: SimEnv, policy: Policy, unit: EpisodeUnit, cfg: Config, stage1_dir: Path) -> EpisodeRecord:
    """Run, record and (maybe) render one episode in this process; write its outputs (not
    its marker). Stage 1's `stream` renders in its render process instead (same files)."""
    v = cfg.stage1.video
    record, states = run_physics(env, policy, unit, cfg, stage1_dir)
    if states is None:
        return record
    folder = Stage1Layout(stage1_dir).episode_dir(unit.key)
    videos = render_videos(env, states, folder, list(v.cameras), v.fps, v.resolution, v.quality)
    return with_videos(record, videos, v.fps)
