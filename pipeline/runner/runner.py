"""The runner: runs a `Stage`'s pending units on an executor and owns the mechanics.

Main process: `pending` skips units whose done marker exists and whose recorded inputs are
still what the stage's `fingerprint` says (a marker from before fingerprints counts as
done; a changed one makes the stage `forget` the old outputs); `execute` shards the units,
hands the shards to the executor, shows one progress bar, and turns a shard whose workers
kept dying (the executor's `SetAside`) into one `set_aside` event per unfinished unit.
Worker: `run_shard` re-checks the markers (a retried shard redoes only unfinished units),
streams the stage's results, writes each done unit's marker last (with its inputs'
fingerprint), and emits one `Event` per unit; a unit that raises `RetryableError` is tried
again in the worker with backoff (retry.py, `executor.retry` in the config), each lost try
a `retry` event, and set aside after the last. Every executor relays the same events.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from pipeline.atomic import Completions
from pipeline.config import RetryConfig
from pipeline.executors.base import Executor, RunReport, SetAside
from pipeline.runner.context import WorkerContext
from pipeline.runner.events import Event
from pipeline.runner.stage import Stage, UnitResult


def is_current(marks: Completions, stage: Stage, unit: Any) -> bool:
    """Done, with the inputs it has now (markers without `inputs` predate them: done)."""
    marker = stage.marker_id(unit)
    if not marks.is_done(marker):
        return False
    fp = stage.fingerprint(unit)
    if fp is None:
        return True
    info = marks.info(marker)
    return info is not None and info.get("inputs", fp) == fp


def finished(stage: Stage, units: list) -> dict[str, dict]:
    """What each unit of `units` that is done with its current inputs recorded, by unit id
    (how a stage reads back its results: certificates, demo summaries)."""
    marks = Completions(stage.root)
    return {stage.unit_id(u): marks.info(stage.marker_id(u)) or {} for u in units if is_current(marks, stage, u)}


def recorded_inputs(stage: Stage, units: list) -> dict[str, Any]:
    """The inputs each done unit of `units` was computed from, by unit id (None: its marker
    predates fingerprints); how a stage refuses to resume over outputs made another way."""
    marks = Completions(stage.root)
    return {stage.unit_id(u): (marks.info(stage.marker_id(u)) or {}).get("inputs")
            for u in units if marks.is_done(stage.marker_id(u))}


def marker_files(root, ids: list[str] | None = None) -> dict[str, Path]:
    """The marker file of each done unit under the stage folder `root` (of `ids`, or all), by
    unit id in sorted order: for a stage whose marker is its record (stage 1's EpisodeRecord)."""
    marks = Completions(root)
    done = marks.done_ids()
    return {u: marks.dir / f"{u}.done" for u in sorted(done if ids is None else set(ids) & done)}


def any_done(root) -> bool:
    """Whether the stage folder `root` holds any done marker (a run to resume, not a fresh one)."""
    return bool(Completions(root).done_ids())


def run_shard(job: tuple, ctx: WorkerContext) -> int:
    """Executor entry point (every executor, every stage): `job` is (stage, units) or (stage,
    units, RetryConfig); returns the units marked done."""
    stage, units, *retry = job
    if retry:
        ctx.retry = retry[0]
    marks = Completions(stage.root)
    todo = [u for u in units if not is_current(marks, stage, u)]
    ran = 0

    def finish(unit: Any, result: UnitResult) -> None:
        nonlocal ran
        if result.done:
            info = dict(result.info)
            if result.inputs is not None:
                info["inputs"] = result.inputs
            marks.mark_done(stage.marker_id(unit), info)  # last: after every output of the unit
            stage.after_done(unit, result)
            ran += 1
        ctx.emit(stage.event("done" if result.done else "set_aside", unit, result))

    stage.stream(todo, ctx, finish)
    return ran


class RunStats(BaseModel):
    """What one `execute` did: units done, their verdicts, what was set aside or retried."""

    model_config = ConfigDict(arbitrary_types_allowed=True)

    ran: int = 0
    ok: int = 0
    statuses: Counter = Counter()
    set_aside: list[Event] = []
    retried: list[Event] = []
    report: RunReport = RunReport()
    wall_s: float = 0.0


class Runner:
    def __init__(self, executor: Executor, console: Console | None = None, retry: RetryConfig | None = None):
        self.executor = executor
        self.console = console or Console()
        # RetryableError policy: given here, else the executor's (make_executor takes it from the config)
        self.retry = retry or getattr(executor, "retry", None) or RetryConfig()

    def pending(self, stage: Stage, units: list) -> list:
        """The units still to do; a done unit whose inputs changed is forgotten and redone."""
        marks = Completions(stage.root)
        done = marks.done_ids()
        todo = []
        for u in units:
            if stage.marker_id(u) in done:
                if is_current(marks, stage, u):
                    continue
                stage.forget(u)
            todo.append(u)
        return todo

    def execute(self, stage: Stage, todo: list, done_before: int = 0,
                on_event: Callable[[Event], None] | None = None) -> RunStats:
        """Run `todo` on the executor with a progress bar; return what happened."""
        stats = RunStats(statuses=Counter())
        t0 = time.perf_counter()
        progress = Progress(TextColumn(f"[bold]{stage.name}"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("{task.fields[note]}"), TimeElapsedColumn(), console=self.console)

        def note() -> str:
            rate = stats.ran / max(time.perf_counter() - t0, 1e-9)
            text = f"{rate:.2f} units/s ok {stats.ok}/{stats.ran}" if stats.ran else "ok -"
            return text + (f" set aside {len(stats.set_aside)}" if stats.set_aside else "")

        with progress:
            bar = progress.add_task(stage.name, total=done_before + len(todo), completed=done_before, note=note())

            def handle(ev: Any) -> None:
                if not isinstance(ev, Event):
                    return  # a stage's own extra events are its business
                if ev.kind == "done":
                    stats.ran += 1
                    stats.ok += bool(ev.ok)
                    stats.statuses[ev.status or "done"] += 1
                    progress.update(bar, advance=1, note=note())
                elif ev.kind == "set_aside":
                    stats.set_aside.append(ev)
                    stats.statuses[f"set_aside:{ev.reason}"] += 1
                    progress.update(bar, advance=1, note=note())
                    first = (ev.detail or "").strip().splitlines()[:1]
                    progress.console.print(f"[red]{stage.name}: set aside[/red] {ev.unit}: {ev.reason}"
                                           + (f": {first[0][:300]}" if first else ""))
                elif ev.kind == "retry":
                    stats.retried.append(ev)
                    progress.console.print(f"[yellow]{stage.name}: retry[/yellow] {ev.unit}: attempt {ev.attempt} "
                                           f"lost ({ev.reason})" + (f"; {ev.detail}" if ev.detail else ""))
                if on_event is not None:
                    on_event(ev)

            shards = stage.shards(todo, self.executor.workers)
            jobs = [(stage, s, self.retry) for s in shards]
            results = self.executor.run(run_shard, jobs, on_event=handle,
                                        label=lambda i, job: stage.shard_label(job[1])) if jobs else []
            marks = Completions(stage.root)
            for (_, shard, _), res in zip(jobs, results):
                if isinstance(res, SetAside):  # its workers kept dying: its unfinished units are set aside
                    for u in shard:
                        if not is_current(marks, stage, u):
                            stage.worker_died(u, res.reason)
                            handle(Event(kind="set_aside", unit=stage.unit_id(u), stage=stage.name,
                                         reason="WorkerDied", detail=res.reason))
            progress.update(bar, note=note())
        stats.report = self.executor.report
        stats.wall_s = time.perf_counter() - t0
        return stats

    def run(self, stage: Stage, cfg, on_event: Callable[[Event], None] | None = None) -> RunStats:
        """Plan, skip what is done, execute the rest."""
        units = stage.units(cfg)
        todo = self.pending(stage, units)
        return self.execute(stage, todo, done_before=len(units) - len(todo), on_event=on_event)
