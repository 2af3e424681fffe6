"""`recover`: the command line of libero-recover.

Each stage command validates the config once (fails before any work, naming file and
key), saves the resolved copy beside the outputs, then hands over to the stage's own
`run(cfg)`. Stage modules are imported lazily so `recover tasks` stays fast.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from pipeline.config import SUITES, Config, load_config
from pipeline.errors import ConfigError, FatalError

app = typer.Typer(add_completion=False, no_args_is_help=True, help=__doc__.splitlines()[0])
console = Console()
err = Console(stderr=True)

CONFIG = typer.Option(Path("configs/smoke.yaml"), "--config", "-c", help="run config (YAML)")
DRY = typer.Option(False, "--dry-run", help="print the resolved config and stop")


def _print_config(cfg: Config) -> None:
    """The resolved config as YAML, verbatim: no wrapping (a long path split over two lines
    is no longer YAML) and no rich markup (a `[...]` in a value is text)."""
    import yaml

    typer.echo(yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False))


def _load(path: Path, dry_run: bool = False) -> Config:
    try:
        cfg = load_config(path)
    except ConfigError as e:
        err.print(f"[red]config error[/red] {e}")
        raise typer.Exit(2) from None
    if dry_run:
        _print_config(cfg)
        raise typer.Exit(0)
    return cfg


def _call(target: str, *args, **kwargs):
    """Run `module:function`, turning project errors into clean exits."""
    module, func = target.split(":")
    try:
        return getattr(importlib.import_module(module), func)(*args, **kwargs)
    except (ConfigError, FatalError) as e:
        err.print(f"[red]{type(e).__name__}[/red] {e}")
        raise typer.Exit(2) from None


@app.command()
def tasks(suite: list[str] = typer.Option(None, "--suite", "-s", help=f"one of {', '.join(SUITES)}")) -> None:
    """List the LIBERO tasks (130 in all)."""
    from pipeline.sim.registry import tasks as list_tasks

    bad = [s for s in suite or [] if s not in SUITES]
    if bad:
        err.print(f"[red]unknown suite(s)[/red] {bad}; choose from {list(SUITES)}")
        raise typer.Exit(2)
    chosen = list_tasks(suite or None)
    table = Table(title=f"LIBERO tasks ({len(chosen)})")
    for col in ("suite", "#", "task", "instruction", "init states"):
        table.add_column(col, overflow="fold")
    for t in chosen:
        table.add_row(t.suite, str(t.index), t.name, t.instruction, str(len(t.init_states())))
    console.print(table)
    counts = {s: sum(t.suite == s for t in chosen) for s in SUITES if any(t.suite == s for t in chosen)}
    console.print(" + ".join(f"{s} {n}" for s, n in counts.items()) + f" = {len(chosen)}")


@app.command("run")
def run_all(config: Path = CONFIG, dry_run: bool = DRY) -> None:
    """Every step in order (pipeline/flow.py): stops at human review, goes on after it; reruns only what is missing."""
    _call("pipeline.flow:run", _load(config, dry_run), config)


@app.command()
def stage1(config: Path = CONFIG, dry_run: bool = DRY,
           rerender: bool = typer.Option(False, "--rerender", help="redraw the run's existing frames (videos, "
                                         "history frames) made by an older renderer from the logged states; "
                                         "no physics is run")) -> None:
    """Stage 1: run failure-generator policies, record states, render failure videos."""
    cfg = _load(config, dry_run)
    _call("pipeline.stage1.rerender:run" if rerender else "pipeline.stage1.run:run", cfg)


@app.command()
def stage2(config: Path = CONFIG, dry_run: bool = DRY) -> None:
    """Stage 2: localize failure onsets, write scene snapshots and histories."""
    _call("pipeline.stage2.run:run", _load(config, dry_run))


@app.command()
def stage3(config: Path = CONFIG, dry_run: bool = DRY) -> None:
    """Stage 3: characterize failures and fill the human review queue."""
    _call("pipeline.stage3.run:run", _load(config, dry_run))


@app.command()
def release(config: Path = CONFIG, dry_run: bool = DRY) -> None:
    """Assemble the scenario set from final reviewed annotations."""
    _call("pipeline.release.build:run", _load(config, dry_run))


@app.command()
def verify(directory: Path = typer.Argument(..., help="a released scenario set"),
           config: Path = typer.Option(None, "--config", "-c",
                                       help="run config: its release checks and executor (default: built-in, inline)"),
           replay: bool = typer.Option(False, "--replay", help="also replay every recovery demo in plain LIBERO"),
           demos: Path = typer.Option(None, "--demos", help="the recovery demos folder (default: recoveries/ "
                                                            "beside the release)")) -> None:
    """Check a scenario set: BDDL, states, restore, goal, settledness, checksums (--replay: demos)."""
    cfg = _load(config) if config is not None else None
    executor = None
    if cfg is not None:
        from pipeline.executors import make_executor

        executor = make_executor(cfg.executor)
    code = _call("pipeline.release.verify:main", directory, cfg.release if cfg else None, replay, demos,
                 executor=executor)
    raise typer.Exit(int(code or 0))


@app.command()
def reproduce(config: Path = CONFIG) -> None:
    """Rebuild the set from scratch and compare checksums with the stored manifest."""
    code = _call("pipeline.release.reproduce:run", _load(config))
    raise typer.Exit(int(code or 0))


@app.command()
def demos(config: Path = CONFIG, dry_run: bool = DRY) -> None:
    """Record recovery demonstrations: recovery-expert rollouts from every released scene."""
    _call("pipeline.release.recovery_demos:run", _load(config, dry_run))


@app.command("export-lerobot")
def export_lerobot(config: Path = CONFIG, out: Path = typer.Option(None, help="output folder"),
                   dataset: list[str] = typer.Option(None, "--dataset", "-d",
                                                     help="rollouts | pre_failure_histories | recoveries (default: all)")
                   ) -> None:
    """Export rollouts, pre-failure histories and recovery demos in the LeRobot v2.1 layout."""
    _call("pipeline.release.lerobot_export:run", _load(config), out, dataset or None)


@app.command("eval")
def evaluate(config: Path = CONFIG, dry_run: bool = DRY,
             split: str = typer.Option(None, "--split", help="eval | train | all: which side of the release's "
                                                             "train/eval split (default: eval.split, `eval`)")) -> None:
    """Evaluate policies on the scenario set: RSR, RD, RC."""
    cfg = _load(config)
    if split is not None:
        if split not in ("eval", "train", "all"):
            err.print(f"[red]--split[/red] must be eval, train or all, got {split!r}")
            raise typer.Exit(2)
        cfg = cfg.model_copy(update={"eval": cfg.eval.model_copy(update={"split": split})})
    if dry_run:
        _print_config(cfg)
        raise typer.Exit(0)
    _call("pipeline.eval.run:run", cfg)


@app.command("bench-localize")
def bench_localize(
    config: Path = CONFIG,
    localizer: str = typer.Option("simstate", "--localizer", "-l", help="simstate | openai | transformers"),
    out: Path = typer.Option(None, help="report folder (default <run>/bench/localize_<localizer>)"),
) -> None:
    """Score a localizer against the scripted generator's own truth on a run folder."""
    report = _call("pipeline.truth.bench:run", _load(config), localizer, out)
    from pipeline.truth.bench import summary_lines

    for line in summary_lines(report):
        console.print(line)
    from pipeline.layout import REPORT, RunLayout

    folder = out or RunLayout.of(_load(config)).bench(localizer)
    console.print(f"report {folder / REPORT}" + (f", plots {len(report['plots'])}" if report["plots"] else ""))


def _add_review() -> None:
    try:
        from pipeline.review.cli import app as review_app
    except ImportError:  # the review package is optional at import time of other commands
        return
    app.add_typer(review_app, name="review", help="Human review queue: serve, status, export, users.")


_add_review()


def main() -> None:  # pragma: no cover
    sys.exit(app())
