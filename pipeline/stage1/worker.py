"""One stage 1 worker: runs a shard of episodes of one task with one reused environment.

Inputs: a `Shard`, the run's `Config` (as a dict, so it pickles cheaply), an optional
policy factory (tests; default `make_policy`), and `emit` for progress events.
Outputs per episode, in `stage1/<episode folder>/`: `states.npy`, `steps.parquet`, videos
and `frames.parquet` when rendered, `truth.parquet` when the policy keeps a truth log
(the scripted generator: `pipeline.policies.scripted.truth`); then the done marker
`stage1/_done/<unit_id>.done` holding the EpisodeRecord (JSON). The videos are drawn by the
worker's render process (render_pool.py) while the physics of the next episodes runs.

Invariants: an episode is `reset_to_init(i)`, `settle(settle_steps)` (zero actions, gripper
open), `policy.reset(task, seed)`, then `run_episode`; the done marker is written last,
after every output (videos included: an episode waiting for its videos has no marker),
so a killed episode is redone (from an emptied folder) on rerun and a
done one is never redone. The environment (and the policy) live across the shards a
worker process runs (`EnvCache`); an exception in one episode is recorded as an `error`
event and the shard goes on, except `FatalError`, which stops the run.
"""

from __future__ import annotations

import shutil
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from pipeline.atomic import Completions, write_text, write_with
from pipeline.config import Config, PolicyConfig
from pipeline.errors import FatalError
from pipeline.layout import EpisodeFiles, Stage1Layout
from pipeline.policies.base import Policy
from pipeline.records import EpisodeRecord
from pipeline.rollout import run_episode
from pipeline.sim import EnvCache, SimEnv
from pipeline.stage1.recorder import EpisodeRecorder
from pipeline.stage1.render_pool import RenderProcess
from pipeline.stage1.units import EpisodeUnit, Shard
from pipeline.stage1.video import render_videos

PolicyFactory = Callable[[PolicyConfig], Policy]

_ENVS: EnvCache | None = None
_POLICY: tuple[str, Policy] | None = None
_RENDER: RenderProcess | None = None


def _render_process() -> RenderProcess:
    """The worker's render process, started on first use and restarted if it died."""
    global _RENDER
    if _RENDER is None or not _RENDER.alive:
        if _RENDER is not None:
            _RENDER.close()
        _RENDER = RenderProcess()
    return _RENDER


def _env(unit: EpisodeUnit) -> SimEnv:
    global _ENVS
    from pipeline.sim.registry import get_task

    if _ENVS is None:
        _ENVS = EnvCache(capacity=1)
    return _ENVS.get(get_task(unit.suite, unit.task))


def _policy(cfg: PolicyConfig, factory: PolicyFactory | None) -> Policy:
    global _POLICY
    key = cfg.model_dump_json() + repr(factory)
    if _POLICY is None or _POLICY[0] != key:
        if _POLICY is not None:
            _POLICY[1].close()
        if factory is None:
            from pipeline.policies.factory import make_policy

            factory = make_policy
        _POLICY = (key, factory(cfg))
    return _POLICY[1]


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
    its marker). `run_shard` renders in its render process instead (same files)."""
    v = cfg.stage1.video
    record, states = run_physics(env, policy, unit, cfg, stage1_dir)
    if states is None:
        return record
    folder = Stage1Layout(stage1_dir).episode_dir(unit.key)
    videos = render_videos(env, states, folder, list(v.cameras), v.fps, v.resolution, v.quality)
    return with_videos(record, videos, v.fps)


def run_shard(job: tuple[Shard, dict, str, PolicyFactory | None], emit) -> int:
    """Executor entry point: run the shard's pending episodes; return how many were run.
    Videos render in the worker's render process while the next episodes run; every
    episode's marker is written once its videos are back, all before this returns."""
    shard, cfg_dict, stage1_dir, factory = job
    cfg = Config.model_validate(cfg_dict)
    v = cfg.stage1.video
    stage1 = Stage1Layout(Path(stage1_dir))
    done = Completions(stage1.root)
    pending = [u for u in shard.units if not done.is_done(u.unit_id)]
    renders = _render_process() if pending and v.render != "none" else None  # spawns while the env builds
    waiting: dict[str, tuple[EpisodeUnit, EpisodeRecord]] = {}
    ran = 0

    def fail(unit: EpisodeUnit, reason: str, detail: str, text: str) -> None:
        write_text(stage1.error(unit.unit_id), text)
        emit({"kind": "error", "unit": unit.unit_id, "reason": reason, "detail": detail})

    def finish(unit: EpisodeUnit, record: EpisodeRecord) -> None:
        nonlocal ran
        done.mark_done(unit.unit_id, record.model_dump(mode="json"))
        stage1.error(unit.unit_id).unlink(missing_ok=True)
        ran += 1
        emit({"kind": "episode", "unit": unit.unit_id, "success": record.success, "steps": record.steps})

    def collect(wait: bool) -> None:
        for ticket, videos, error in renders.results(wait) if renders is not None else []:
            unit, record = waiting.pop(ticket)
            if error is None:
                finish(unit, with_videos(record, videos, v.fps))
            else:
                fail(unit, "RenderError", error.strip().splitlines()[-1], error)

    try:
        for unit in pending:
            try:
                env = _env(unit)
                if renders is not None and not renders.alive:  # fail what it held, take a fresh one
                    collect(wait=False)
                    renders = _render_process()
                if renders is not None:
                    renders.prepare(env, v.resolution, v.quality)  # model loads during the physics
                record, states = run_physics(env, _policy(cfg.stage1.policy, factory), unit, cfg, stage1.root)
                if states is not None:
                    renders.submit(unit.unit_id, env, states, stage1.episode_dir(unit.key), list(v.cameras), v.fps,
                                   v.resolution, v.quality)
            except FatalError:
                raise
            except Exception as e:  # one episode's failure must not cost the others
                fail(unit, type(e).__name__, str(e), traceback.format_exc())
                continue
            if states is None:
                finish(unit, record)
            else:
                waiting[unit.unit_id] = (unit, record)
            collect(wait=False)
    finally:
        collect(wait=True)  # also on a fatal error: finished videos still get their markers
    return ran
