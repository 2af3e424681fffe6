"""Stage 1 entry point: `run(cfg)` rolls out the failure-generator policy on every
selected (task, init state) and records the episodes (`recover stage1`, `make stage1`).

Inputs: a validated `Config` (tasks, stage1 policy/rollout/video, executor).
Outputs under `run.output_dir`: `config.resolved.yaml` (also `stage1/config.resolved.yaml`),
the episode folders and done markers (see `pipeline.records`), `stage1/episodes.parquet`
(the manifest, rebuilt from the markers at the end of every run), `stage1/summary.json`
(with `executor`: the attempts lost to dead workers, also logged by the executor).

Invariants: rerunning the same command skips done episodes and finishes the others, so
a crash or kill followed by a rerun leaves every planned episode exactly once; resuming
into a folder made with a different policy/rollout config or seed is refused, because
it would mix episodes of two experiments.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import yaml
from rich.console import Console

from pipeline.config import Config, save_resolved
from pipeline.errors import ConfigError
from pipeline.executors import Executor, make_executor
from pipeline.layout import RESOLVED_CONFIG, RunLayout
from pipeline.runner import Runner
from pipeline.runner.runner import any_done
from pipeline.stage1.stage import Stage1
from pipeline.stage1.summary import collect_records, summarize, summary_table, write_manifest, write_summary

# Extra environment of each worker process. Mesa's llvmpipe starts one render thread per
# core in every worker, so LP_NUM_THREADS=1 looked worth trying with one worker per core; on
# a busy 2-core machine it measured slower (benchmarks/stage1_throughput.py compares both),
# and a frame costs the same CPU with 1 or 2 llvmpipe threads (benchmarks/render_cost.py:
# the threads share only the pixel work), while Mesa's default lets a lone worker's render
# process use the core its physics leaves idle; so Mesa's default is kept.
WORKER_ENV: dict[str, str] = {}


def _experiment(cfg: Config) -> dict:
    """What must not change between a run and its resumption."""
    return {"seed": cfg.run.seed, "policy": cfg.stage1.policy.model_dump(mode="json"),
            "rollout": cfg.stage1.rollout.model_dump(mode="json")}


def _check_resumable(cfg: Config, stage1: Path) -> None:
    saved = stage1 / RESOLVED_CONFIG
    if not saved.exists() or not any_done(stage1):
        return
    old = Config.model_validate(yaml.safe_load(saved.read_text()))
    if _experiment(old) != _experiment(cfg):
        raise ConfigError(
            f"{saved}: {stage1} holds episodes of a different run seed/policy/rollout config; "
            "use a new run.output_dir (or delete the old one) instead of mixing experiments"
        )


def run(
    cfg: Config,
    policy_factory: Callable | None = None,
    executor: Executor | None = None,
    console: Console | None = None,
) -> dict:
    console = console or Console()
    s1 = RunLayout.of(cfg).stage1
    stage1 = s1.root
    _check_resumable(cfg, stage1)
    save_resolved(cfg, cfg.out)
    save_resolved(cfg, stage1)

    stage = Stage1(cfg, policy_factory)
    units = stage.units(cfg)
    runner = Runner(executor or make_executor(cfg.executor, worker_env=WORKER_ENV), console=console)
    pending = runner.pending(stage, units)
    shards = stage.shards(pending, runner.executor.workers)
    console.print(
        f"stage 1: {len(units)} episodes planned, {len(units) - len(pending)} already done, "
        f"{len(pending)} to run in {len(shards)} shard(s) on {runner.executor.workers} worker(s) -> {stage1}"
    )
    t0 = time.perf_counter()
    stats = runner.execute(stage, pending, done_before=len(units) - len(pending))
    # every episode set aside (an exception, a dead render process, a shard whose worker kept
    # dying) is an error: counted here, its file in stage1/errors/, retried on rerun
    errors = [{"kind": "error", "unit": ev.unit, "reason": ev.reason, "detail": ev.detail} for ev in stats.set_aside]

    records = collect_records(stage1, [u.unit_id for u in units])
    manifest = write_manifest(stage1, records)
    rows = summarize(records)
    elapsed = time.perf_counter() - t0
    write_summary(stage1, rows, {"planned": len(units), "done": len(records), "errors": errors,
                                 "ran_this_time": stats.ran, "wall_s": round(elapsed, 2),
                                 "executor": stats.report.model_dump(mode="json")})
    console.print(summary_table(rows))
    missing = len(units) - len(records)
    msg = f"manifest {manifest} ({len(records)}/{len(units)} episodes)"
    if missing:
        msg += f"; [red]{missing} episode(s) not done[/red] (errors in {s1.errors_dir}); rerun the same command to retry"
    console.print(msg)
    return {"planned": len(units), "done": len(records), "ran": stats.ran, "errors": errors,
            "manifest": str(manifest), "wall_s": elapsed}
