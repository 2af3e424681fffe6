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
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from pipeline.atomic import Completions, write_text
from pipeline.config import Config, save_resolved
from pipeline.errors import ConfigError
from pipeline.executors import Executor, SetAside, make_executor
from pipeline.layout import RESOLVED_CONFIG, RunLayout
from pipeline.stage1.summary import collect_records, summarize, summary_table, write_manifest, write_summary
from pipeline.stage1.units import Shard, make_shards, plan_units
from pipeline.stage1.worker import run_shard

# Extra environment of each worker process. Mesa's llvmpipe starts one render thread per
# core in every worker, so LP_NUM_THREADS=1 looked worth trying with one worker per core; on
# a busy 2-core machine it measured slower (benchmarks/stage1_throughput.py compares both),
# so Mesa's default is kept until a quiet measurement says otherwise.
WORKER_ENV: dict[str, str] = {}


def _experiment(cfg: Config) -> dict:
    """What must not change between a run and its resumption."""
    return {"seed": cfg.run.seed, "policy": cfg.stage1.policy.model_dump(mode="json"),
            "rollout": cfg.stage1.rollout.model_dump(mode="json")}


def _check_resumable(cfg: Config, stage1: Path) -> None:
    saved = stage1 / RESOLVED_CONFIG
    if not saved.exists() or not Completions(stage1).done_ids():
        return
    old = Config.model_validate(yaml.safe_load(saved.read_text()))
    if _experiment(old) != _experiment(cfg):
        raise ConfigError(
            f"{saved}: {stage1} holds episodes of a different run seed/policy/rollout config; "
            "use a new run.output_dir (or delete the old one) instead of mixing experiments"
        )


def _shard_label(shard: Shard) -> str:
    suite, task = shard.task
    return f"shard {suite}/{task} init states {','.join(str(u.init_state) for u in shard.units)}"


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

    units = plan_units(cfg)
    done = Completions(stage1)
    pending = [u for u in units if not done.is_done(u.unit_id)]
    executor = executor or make_executor(cfg.executor, worker_env=WORKER_ENV)
    shards = make_shards(pending, executor.workers)
    console.print(
        f"stage 1: {len(units)} episodes planned, {len(units) - len(pending)} already done, "
        f"{len(pending)} to run in {len(shards)} shard(s) on {executor.workers} worker(s) -> {stage1}"
    )

    stats = {"ran": 0, "ok": 0, "errors": []}
    t0 = time.perf_counter()
    progress = Progress(
        TextColumn("[bold]stage 1"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[rate]}"),
        TextColumn("{task.fields[succ]}"), TimeElapsedColumn(), console=console, transient=False,
    )

    def fields() -> dict:
        n = stats["ran"]
        rate = n / max(time.perf_counter() - t0, 1e-9)
        return {"rate": f"{rate:.2f} ep/s", "succ": f"success {stats['ok']}/{n}" if n else "success -"}

    with progress:
        bar = progress.add_task("episodes", total=len(units), completed=len(units) - len(pending), **fields())

        def on_event(ev: dict) -> None:
            if ev["kind"] == "episode":
                stats["ran"] += 1
                stats["ok"] += int(ev["success"])
                progress.update(bar, advance=1, **fields())
            elif ev["kind"] == "error":
                stats["errors"].append(ev)
                progress.console.print(f"[red]episode error[/red] {ev['unit']}: {ev['reason']}: {ev['detail']}")

        jobs = [(s, cfg.model_dump(mode="json"), str(stage1), policy_factory) for s in shards]
        results = executor.run(run_shard, jobs, on_event, label=lambda i, job: _shard_label(job[0]))
        progress.update(bar, **fields())
    # a shard whose worker kept dying: its unfinished episodes are errors, counted and retried on rerun
    for shard, res in zip(shards, results):
        if isinstance(res, SetAside):
            for u in shard.units:
                if not done.is_done(u.unit_id):
                    write_text(s1.error(u.unit_id), f"worker died: {res.reason}\n")
                    stats["errors"].append({"kind": "error", "unit": u.unit_id, "reason": "WorkerDied",
                                            "detail": res.reason})

    records = collect_records(stage1, [u.unit_id for u in units])
    manifest = write_manifest(stage1, records)
    rows = summarize(records)
    elapsed = time.perf_counter() - t0
    write_summary(stage1, rows, {"planned": len(units), "done": len(records), "errors": stats["errors"],
                                 "ran_this_time": stats["ran"], "wall_s": round(elapsed, 2),
                                 "executor": executor.report.model_dump(mode="json")})
    console.print(summary_table(rows))
    missing = len(units) - len(records)
    msg = f"manifest {manifest} ({len(records)}/{len(units)} episodes)"
    if missing:
        msg += f"; [red]{missing} episode(s) not done[/red] (errors in {s1.errors_dir}); rerun the same command to retry"
    console.print(msg)
    return {"planned": len(units), "done": len(records), "ran": stats["ran"], "errors": stats["errors"],
            "manifest": str(manifest), "wall_s": elapsed}
