"""`recover eval`: run the recovery evaluation and write records, metrics and the report.

Inputs: a validated `Config` (section `eval`), the scenes (`plan.default_scenes_dir`) and,
for RD, the stage-1 rollouts they were cut from.
Outputs under `<run.output_dir>/eval/`: `config.resolved.yaml`, `trials/<unit>.parquet`
and `_done/<unit>.done` per trial, `quarantine.jsonl` (trials that could not run, with the
reason), `episodes.parquet` (all rows of this plan), `metrics.json`, `report.md` + PNGs.

Invariants: resumable: a trial's row is written atomically, then its marker; a rerun skips
marked trials and re-gathers. Workers (the configured executor) each keep one environment
(the current task's) and one instance of each policy alive across their trials.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from pipeline.atomic import Completions, write_json, write_text
from pipeline.config import Config, save_resolved
from pipeline.errors import EpisodeError, FatalError
from pipeline.eval.plan import Shard, default_scenes_dir, plan_trials, shard
from pipeline.eval.records import EvalEpisode, read_episodes, write_episodes
from pipeline.eval.scenes import find_scenes
from pipeline.layout import EvalLayout, RunLayout

WORKER_ENV = {"MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"}

# per worker process: the current task's environment and the built policies
_ENVS = None
_POLICIES: dict[str, object] = {}


def _policy(name: str, chunk_size: int, shard_: Shard):
    """The worker's instance of a policy at a chunk size (built once per process)."""
    key = f"{name}@{chunk_size}"
    if key not in _POLICIES:
        from pipeline.eval.plan import policy_name
        from pipeline.policies.factory import make_policy

        cfg = next(p for p in shard_.policies if policy_name(p) == name)
        if cfg.kind == "scripted":  # let the expert plan chunks as long as the runner executes
            cfg = cfg.model_copy(update={"scripted": cfg.scripted.model_copy(update={"chunk_len": chunk_size})})
        _POLICIES[key] = make_policy(cfg)
    return _POLICIES[key]


def run_shard(item: tuple[Shard, str], emit) -> int:
    """Worker: run a shard's trials, writing each row then its marker; returns trials run."""
    global _ENVS
    shard_, out_dir = item
    out = Path(out_dir)
    from pipeline.eval.scenes import scene_task
    from pipeline.eval.protocol import run_trial
    from pipeline.sim import EnvCache

    if _ENVS is None:
        _ENVS = EnvCache(capacity=1)
    done = Completions(out)
    for trial in shard_.trials:
        uid = trial.unit_id
        try:
            env = _ENVS.get(scene_task(trial.scene))
            ep = run_trial(env, _policy(trial.policy, trial.chunk_size, shard_), trial)
        except EpisodeError as e:
            write_json(EvalLayout(out).quarantine(uid), {"unit_id": uid, "scene_id": trial.scene.scene_id,
                                                            "reason": e.reason, "detail": e.detail})
            emit(("error", uid, e.reason))
            continue
        write_episodes(EvalLayout(out).trial(uid), [ep])
        done.mark_done(uid, {"success": ep.success, "steps": ep.steps})
        EvalLayout(out).quarantine(uid).unlink(missing_ok=True)  # an earlier failed attempt
        emit(("done", uid, ep.success))
    return len(shard_.trials)


def _execute(cfg: Config, shards: list[Shard], out: Path, total: int) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from pipeline.executors import make_executor
    from pipeline.executors.local import InlineExecutor

    executor = InlineExecutor() if cfg.executor.workers == 1 and cfg.executor.kind == "local" else \
        make_executor(cfg.executor, worker_env=WORKER_ENV)
    with Progress(TextColumn("eval"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[note]}"),
                  TimeElapsedColumn()) as bar:
        task = bar.add_task("trials", total=total, note="")
        wins = [0, 0]

        def on_event(ev) -> None:
            kind, _uid, info = ev
            if kind == "done":
                wins[0] += bool(info)
                wins[1] += 1
            bar.update(task, advance=1, note=f"{wins[0]}/{wins[1]} recovered" + (" (quarantined one)" if kind == "error" else ""))

        try:
            executor.run(run_shard, [(s, str(out)) for s in shards], on_event=on_event)
        finally:
            release_worker_state()  # inline runs keep them in this process


def release_worker_state() -> None:
    """Close this process's cached environment and policies (EGL contexts, sockets)."""
    global _ENVS
    if _ENVS is not None:
        _ENVS.close()
        _ENVS = None
    for p in _POLICIES.values():
        p.close()
    _POLICIES.clear()


def gather(out: Path, unit_ids: list[str]) -> list[EvalEpisode]:
    rows: list[EvalEpisode] = []
    for uid in unit_ids:
        p = EvalLayout(out).trial(uid)
        if p.is_file():
            rows += read_episodes(p)
    return rows


def run(cfg: Config) -> Path:
    for k, v in WORKER_ENV.items():
        os.environ.setdefault(k, v)
    layout = RunLayout.of(cfg).eval
    out = layout.root
    out.mkdir(parents=True, exist_ok=True)
    save_resolved(cfg, out)
    scenes_dir = default_scenes_dir(cfg)
    try:
        scenes, problems = find_scenes(scenes_dir)
    except (FileNotFoundError, ValueError) as e:
        raise FatalError(f"eval: cannot read scenes: {e}") from None
    if cfg.eval.max_scenes is not None:
        scenes = scenes[: cfg.eval.max_scenes]
    if not scenes:
        raise FatalError(f"eval: no scenes under {scenes_dir} (run stage 2 or release first, or set eval.scenes_dir)")
    trials, rd_problems = plan_trials(cfg, scenes)
    problems += rd_problems
    done = Completions(out).done_ids()
    todo = [t for t in trials if t.unit_id not in done]
    if todo:
        _execute(cfg, shard(todo, list(cfg.eval.policies), cfg.executor.workers), out, len(todo))
    episodes = gather(out, [t.unit_id for t in trials])
    write_episodes(layout.episodes, episodes)
    planned = {t.unit_id for t in trials}
    quarantine = [p for p in sorted(layout.quarantine_dir.glob("*.json")) if p.stem in planned] \
        if layout.quarantine_dir.is_dir() else []
    write_text(layout.quarantine_log, "".join(json.dumps(json.loads(p.read_text())) + "\n" for p in quarantine))
    from pipeline.eval.records import read_rows
    from pipeline.eval.report import write_report

    write_report(read_rows(layout.episodes), cfg.eval, out, scenes_dir=scenes_dir, problems=problems,
                 planned=len(trials))
    return out
