"""`recover run`: every step of a run, in order, declared once (`STEPS`).

A step is one of the project's commands, each of which still runs alone (`recover stage1`,
...). `run` walks `STEPS`: a step with nothing to do says so and is skipped, one with work
runs; the review gate stops the walk while items await human review, saying how many and
how to review them, and the next call (after review) goes on through the review export,
release, recovery demonstrations and the LeRobot export. A call with nothing left to do
runs nothing and says so.

Whether a step has work is the runner's answer, never a second set of markers: a stage of
units (stage 1-3, demos) has work while some unit's done marker is missing or its inputs
changed (`is_current`); a whole-run step (review export, release, LeRobot export) is the
one unit of a `WholeStep` stage whose marker, `<run>/pipeline/_done/<step>.done`, records
a hash of the step's inputs, so it runs again only when they changed.
"""

from __future__ import annotations

import hashlib
import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.markup import escape

from pipeline.config import Config
from pipeline.layout import RunLayout
from pipeline.runner import Stage, UnitResult, WorkerContext


@dataclass(frozen=True)
class Step:
    name: str
    command: str  # how to run it alone
    target: str = ""  # "module:function" called with (cfg, config path)
    stage: Callable[[Config], Stage] | None = None  # a stage of units: pending markers say if it has work
    inputs: Callable[[Config], Any] | None = None  # a whole-run step: what its outputs are computed from
    gate: Callable[[Config], tuple[int, str]] | None = None  # human work waiting (count, what), stops the walk

    def call(self, cfg: Config, path: Path) -> None:
        module, func = self.target.split(":")
        getattr(importlib.import_module(module), func)(cfg, path)


# ---- the steps' entry points and their inputs ---------------------------------------------------

def stage1(cfg: Config, path: Path) -> None:
    from pipeline.stage1.run import run

    run(cfg)


def stage2(cfg: Config, path: Path) -> None:
    from pipeline.stage2.run import run

    run(cfg)


def stage3(cfg: Config, path: Path) -> None:
    from pipeline.stage3.run import run

    run(cfg)


def review_export(cfg: Config, path: Path) -> None:
    from pipeline.review.cli import export

    export(config=path, out=None)


def release(cfg: Config, path: Path) -> None:
    from pipeline.release.build import run

    run(cfg)


def demos(cfg: Config, path: Path) -> None:
    from pipeline.release.recovery_demos import run

    run(cfg)


def export_lerobot(cfg: Config, path: Path) -> None:
    from pipeline.release.lerobot_export import run

    run(cfg)


def _stage1(cfg: Config) -> Stage:
    from pipeline.stage1.stage import Stage1

    return Stage1(cfg)


def _stage2(cfg: Config) -> Stage:
    from pipeline.stage2.stage import Stage2

    return Stage2(cfg)


def _stage3(cfg: Config) -> Stage:
    from pipeline.stage3.run import Stage3

    return Stage3(cfg)


def _demos(cfg: Config) -> Stage:
    from pipeline.release.manifest import read_manifest
    from pipeline.release.recovery_demos import DemoStage, train_rows

    return DemoStage(cfg, train_rows(read_manifest(RunLayout.of(cfg).release.manifest)))  # as `recover demos`


def _hash(*parts: Any) -> str:
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, Path):  # a file's or a folder's bytes, names included
            files = sorted(f for f in p.rglob("*") if f.is_file()) if p.is_dir() else [p] if p.is_file() else []
            h.update(f"{p}:{len(files)}\n".encode())
            for f in files:
                h.update(f.relative_to(p).as_posix().encode() if f != p else b"")
                h.update(hashlib.sha256(f.read_bytes()).digest())
        else:
            h.update(json.dumps(p, sort_keys=True, default=str).encode())
    return h.hexdigest()


def _final_reviews(cfg: Config) -> str:
    """What the review export would write: the final annotations in the review database."""
    from pipeline.review.db import read_session
    from pipeline.review.export import annotation, final_items
    from pipeline.review.server import engine_for

    with read_session(engine_for(cfg)) as s:
        return _hash([annotation(s, i).model_dump(mode="json") for i in final_items(s)])


def _release_inputs(cfg: Config) -> str:
    runs = [RunLayout.of(cfg)] + [RunLayout(Path(r)) for r in cfg.release.merge_runs]  # merged runs too
    return _hash(*(p for run in runs for p in (run.stage3.annotations, run.stage2.localizations_dir,
                                              run.stage1.manifest)),
                 cfg.release.model_dump(mode="json"), cfg.stage1.rollout.model_dump(mode="json"))


def _lerobot_inputs(cfg: Config) -> str:
    run = RunLayout.of(cfg)
    return _hash(run.release.manifest, run.recoveries.demos, run.stage1.manifest, cfg.release.model_dump(mode="json"))


def _review_gate(cfg: Config) -> tuple[int, str]:
    from pipeline.review import views
    from pipeline.review.db import read_session
    from pipeline.review.server import engine_for
    from pipeline.vocab import ItemStatus

    with read_session(engine_for(cfg)) as s:
        counts = views.counts(s)
    waiting = {k: n for k, n in counts["by_status"].items() if k not in (ItemStatus.final, ItemStatus.superseded)}
    return sum(waiting.values()), f"of {counts['total']} queue items ({', '.join(f'{k} {n}' for k, n in sorted(waiting.items()))})"


STEPS: tuple[Step, ...] = (
    Step("stage1", "recover stage1", "pipeline.flow:stage1", stage=_stage1),
    Step("stage2", "recover stage2", "pipeline.flow:stage2", stage=_stage2),
    Step("stage3", "recover stage3", "pipeline.flow:stage3", stage=_stage3),
    Step("review", "recover review serve", gate=_review_gate),
    Step("review-export", "recover review export", "pipeline.flow:review_export", inputs=_final_reviews),
    Step("release", "recover release", "pipeline.flow:release", inputs=_release_inputs),
    Step("demos", "recover demos", "pipeline.flow:demos", stage=_demos),
    Step("export-lerobot", "recover export-lerobot", "pipeline.flow:export_lerobot", inputs=_lerobot_inputs),
)


# ---- whole-run steps as one-unit stages: the runner's markers say whether they are current ------

@dataclass
class WholeStep(Stage[str]):
    cfg: Config
    step: Step
    path: Path  # the config file (the review export reads it)
    name: str = "step"

    @property
    def root(self) -> Path:
        return RunLayout.of(self.cfg).pipeline

    def units(self, cfg: Config) -> list[str]:
        return [self.step.name]

    def unit_id(self, unit: str) -> str:
        return unit

    def fingerprint(self, unit: str) -> str:
        return self.step.inputs(self.cfg)

    def process(self, unit: str, ctx: WorkerContext) -> UnitResult:
        self.step.call(self.cfg, self.path)
        return UnitResult()


def pending(step: Step, cfg: Config, path: Path) -> int:
    """How many units of `step` are not done with their current inputs."""
    from pipeline.runner.runner import finished

    stage = step.stage(cfg) if step.stage is not None else WholeStep(cfg, step, path)
    units = stage.units(cfg)
    return len(units) - len(finished(stage, units))


def run(cfg: Config, path: Path, console: Console | None = None) -> str:
    """Walk the steps; return "review" when stopped at the review gate, "done" when through,
    "nothing" when no step had anything to do."""
    from pipeline.runner.runner import run_shard

    console = console or Console()
    ran = 0
    for step in STEPS:
        if step.gate is not None:
            waiting, what = step.gate(cfg)
            if waiting:
                # soft_wrap: the commands stay whole when copied from a narrow terminal or a log
                console.print(f"[bold yellow]stopped at human review[/bold yellow]: {waiting} {escape(what)} await "
                              f"review. Review them (`{step.command} --config {escape(str(path))}`, the review page), "
                              f"then run `recover run --config {escape(str(path))}` again to go on with "
                              f"{', '.join(s.name for s in STEPS[STEPS.index(step) + 1:])}.", soft_wrap=True)
                return "review"
            console.print(f"[green]{step.name}[/green]: nothing awaits review")
            continue
        todo = pending(step, cfg, path)
        if not todo:
            console.print(f"[green]{step.name}[/green]: up to date")
            continue
        console.rule(f"{step.name} ({step.command})")
        ran += 1
        if step.stage is not None:
            step.call(cfg, path)
        else:  # its marker, with the inputs' hash, is written after it ran
            run_shard((WholeStep(cfg, step, path), (step.name,)), WorkerContext())
    if not ran:
        console.print("[bold green]nothing to do[/bold green]: every step is up to date")
        return "nothing"
    console.print(f"[bold green]done[/bold green]: {ran} step(s) ran; every step is up to date")
    return "done"
