"""One stage 1 worker: runs a shard of episodes of one task with one reused environment.

Inputs: a `Shard`, the run's `Config` (as a dict, so it pickles cheaply), an optional
policy factory (tests; default `make_policy`), and `emit` for progress events.
Outputs per episode, in `stage1/<episode folder>/`: `states.npy`, `steps.parquet`, videos
and `frames.parquet` when rendered, `truth.parquet` when the policy keeps a truth log
(the scripted generator: `pipeline.policies.scripted.truth`); then the done marker `stage1/_done/<unit_id>.done`
holding the EpisodeRecord (JSON).

Invariants: an episode is `reset_to_init(i)`, `settle(settle_steps)` (zero actions, gripper
open), `policy.reset(task, seed)`, then `run_episode`; the done marker is written last,
after every output, so a killed episode is redone (from an emptied folder) on rerun and a
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

import pyarrow.parquet as pq

from pipeline.atomic import Completions, write_text, write_with
from pipeline.config import Config, PolicyConfig
from pipeline.errors import FatalError
from pipeline.policies.base import Policy
from pipeline.records import EpisodeRecord
from pipeline.rollout import run_episode
from pipeline.sim import EnvCache, SimEnv
from pipeline.stage1.recorder import EpisodeRecorder
from pipeline.stage1.units import EpisodeUnit, Shard
from pipeline.stage1.video import render_videos

PolicyFactory = Callable[[PolicyConfig], Policy]

_ENVS: EnvCache | None = None
_POLICY: tuple[str, Policy] | None = None


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


def run_one(env: SimEnv, policy: Policy, unit: EpisodeUnit, cfg: Config, stage1_dir: Path) -> EpisodeRecord:
    """Run, record and (maybe) render one episode; write its outputs (not its marker)."""
    r, v = cfg.stage1.rollout, cfg.stage1.video
    folder = stage1_dir / unit.rel_dir
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
        write_with(folder / "truth.parquet", lambda p: pq.write_table(truth, p))
    videos: dict[str, str] = {}
    if should_render(v.render, result.success):
        videos = render_videos(env, rec.states_array(), folder, list(v.cameras), v.fps, v.resolution, v.quality)
    return EpisodeRecord(
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
        videos=videos,
        video_fps=v.fps if videos else None,
    )


def run_shard(job: tuple[Shard, dict, str, PolicyFactory | None], emit) -> int:
    """Executor entry point: run the shard's pending episodes; return how many were run."""
    shard, cfg_dict, stage1_dir, factory = job
    cfg = Config.model_validate(cfg_dict)
    stage1 = Path(stage1_dir)
    done = Completions(stage1)
    ran = 0
    for unit in shard.units:
        if done.is_done(unit.unit_id):
            continue
        try:
            env = _env(unit)
            record = run_one(env, _policy(cfg.stage1.policy, factory), unit, cfg, stage1)
        except FatalError:
            raise
        except Exception as e:  # one episode's failure must not cost the others
            detail = traceback.format_exc()
            write_text(stage1 / "errors" / f"{unit.unit_id}.txt", detail)
            emit({"kind": "error", "unit": unit.unit_id, "reason": type(e).__name__, "detail": str(e)})
            continue
        done.mark_done(unit.unit_id, record.model_dump(mode="json"))
        (stage1 / "errors" / f"{unit.unit_id}.txt").unlink(missing_ok=True)
        ran += 1
        emit({"kind": "episode", "unit": unit.unit_id, "success": record.success, "steps": record.steps})
    return ran
