"""`recover review ...`: serve the review page, queue status, people, export, history.

Every command reads the run config (`--config`), so the database and run folder are the
ones stage 3 filled. Heavy imports (SQLAlchemy, FastAPI, matplotlib) happen inside the
commands: importing this module stays cheap for `recover --help`.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from pipeline.layout import RunLayout, Stage3Layout

app = typer.Typer(add_completion=False, no_args_is_help=True, help="Human review queue.")
CONFIG = typer.Option(Path("configs/smoke.yaml"), "--config", "-c", help="run config (YAML)")


def _cfg(path: Path):
    from rich.console import Console

    from pipeline.config import load_config
    from pipeline.errors import ConfigError

    try:
        return load_config(path)
    except ConfigError as e:
        from rich.markup import escape

        from pipeline.review.terminal import safe

        Console(stderr=True).print(f"[red]config error[/red] {escape(safe(e))}")
        raise typer.Exit(2) from None


@app.command()
def serve(config: Path = CONFIG, host: str = typer.Option(None, help="default: stage3.host"),
          port: int = typer.Option(None, help="default: stage3.port"),
          docs: bool = typer.Option(False, "--docs", help="serve /api/docs and /api/openapi.json (signed in)"),
          workers: int = typer.Option(None, min=1, help="server processes (default: stage3.workers); "
                                                         "SQLite stays consistent across them"),
          ) -> None:
    """Serve the review web page and API."""
    from pipeline.review.server import serve as run_server

    from pipeline.errors import FatalError
    from pipeline.rendered import require_current_frames, run_frame_tables

    cfg = _cfg(config)
    try:  # reviewers judge these videos: never ones of the old renderer
        require_current_frames(run_frame_tables(cfg), "the review server")
    except FatalError as e:
        typer.echo(f"FatalError {e}", err=True)
        raise typer.Exit(2) from None
    host, port = host or cfg.stage3.host, port or cfg.stage3.port
    workers = workers or cfg.stage3.workers
    typer.echo(f"review page: http://{host}:{port}/  (run folder {cfg.out}, {workers} process(es))")
    run_server(config, cfg, host, port, workers, docs)


@app.command("add-reviewer")
def add_reviewer(name: str = typer.Argument(..., help="a person's name (unique)"),
                 role: str = typer.Option("reviewer", help="reviewer | adjudicator | admin"),
                 config: Path = CONFIG) -> None:
    """Create a person (or give them a new token); prints their personal token once."""
    from pipeline.review.auth import ROLES, add_user
    from pipeline.review.server import engine_for

    if role not in ROLES:
        typer.echo(f"role must be one of {', '.join(ROLES)}", err=True)
        raise typer.Exit(2)
    token = add_user(engine_for(_cfg(config)), name, role, actor="cli")
    typer.echo(f"{name} ({role}) token: {token}")
    typer.echo("Keep it secret: only its hash is stored; run add-reviewer again to replace it.")


reviewers = typer.Typer(add_completion=False, no_args_is_help=True, help="List, deactivate or reactivate people.")
app.add_typer(reviewers, name="reviewers")


@reviewers.command("list")
def reviewers_list(config: Path = CONFIG) -> None:
    """Every person with their role and whether they may sign in."""
    from rich.console import Console
    from rich.table import Table

    from pipeline.review.auth import list_users
    from pipeline.review.server import engine_for

    from pipeline.review.terminal import cell

    table = Table(title="reviewers")
    for col in ("name", "role", "active"):
        table.add_column(col)
    for u in list_users(engine_for(_cfg(config))):
        table.add_row(cell(u["name"]), cell(u["role"]), "yes" if u["active"] else "[red]no[/red]")
    Console(width=120).print(table)


def _set_active(name: str, active: bool, config: Path) -> None:
    from pipeline.review.auth import set_active
    from pipeline.review.server import engine_for

    try:
        changed = set_active(engine_for(_cfg(config)), name, active, actor="cli")
    except LookupError as e:
        typer.echo(str(e), err=True)
        raise typer.Exit(2) from None
    state = "active" if active else "deactivated"
    typer.echo(f"{name}: {state}" if changed else f"{name} was already {state}")


@reviewers.command("deactivate")
def reviewers_deactivate(name: str = typer.Argument(..., help="the person's name"), config: Path = CONFIG) -> None:
    """Refuse this person's token and sessions from now on; their leases are released."""
    _set_active(name, False, config)


@reviewers.command("reactivate")
def reviewers_reactivate(name: str = typer.Argument(..., help="the person's name"), config: Path = CONFIG) -> None:
    """Accept this person's existing token again."""
    _set_active(name, True, config)


@app.command()
def status(config: Path = CONFIG, as_json: bool = typer.Option(False, "--json", help="print JSON")) -> None:
    """Queue counts and agreement statistics; writes the confusion-matrix PNG beside them."""
    from pipeline.atomic import write_json
    from pipeline.review import report, truth_view, views
    from pipeline.review.db import read_session, write_session
    from pipeline.review.server import engine_for, settings
    from pipeline.review.workflow import expire

    cfg = _cfg(config)
    engine = engine_for(cfg)
    with write_session(engine) as s:
        expire(s)
    tau = settings(cfg).time_tolerance_s
    with read_session(engine) as s:
        out = {"counts": views.counts(s), **report.summary(s, tau)}
        # beside model vs reviewers: model vs the scripted generator's truth, when it wrote one
        out["model_vs_truth"] = truth_view.compare(report.current_items(s), cfg.out, tau,
                                                   cfg.stage1.rollout.control_hz)
    s3 = RunLayout.of(cfg).stage3
    write_json(s3.review_status, out)
    png = report.plot(out, s3.review_confusion)
    if as_json:
        typer.echo(json.dumps(out, indent=2))
    else:
        from pipeline.review.status_view import render

        render(out)
    typer.echo(f"wrote {s3.review_status} and {png}")


@app.command()
def export(config: Path = CONFIG, out: Path = typer.Option(None, help="default: <run>/stage3/annotations")) -> None:
    """Write final records as JSON per episode plus annotations.parquet."""
    from pipeline.review.db import read_session
    from pipeline.review.export import export as do_export
    from pipeline.review.server import engine_for, settings

    cfg = _cfg(config)
    root = out or RunLayout.of(cfg).stage3.annotations
    with read_session(engine_for(cfg)) as s:
        files = do_export(s, root, run_dir=cfg.out, control_hz=cfg.stage1.rollout.control_hz,
                          tau=settings(cfg).time_tolerance_s)
    typer.echo(f"exported {len(files)} final record(s) to {root}")
    if (root / Stage3Layout.MODEL_VS_TRUTH).is_file():
        typer.echo(f"model and final records vs the generator's truth: {root / Stage3Layout.MODEL_VS_TRUTH}")


@app.command()
def schema(out: Path = typer.Option(Path("annotations/schema.json"), help="where to write it")) -> None:
    """Write the JSON schema of exported annotation files (from `records.Annotation`)."""
    from pipeline.review.export import write_schema

    typer.echo(f"wrote {write_schema(out)}")


@app.command()
def history(item: str = typer.Argument(..., help="item id or episode key <suite>/<task>/<episode_id>"),
            config: Path = CONFIG) -> None:
    """Every audit event of an item (all revisions of an episode key), oldest first."""
    from rich.console import Console
    from rich.table import Table

    from pipeline.review.audit import history as get_history
    from pipeline.review.db import read_session
    from pipeline.review.server import engine_for

    with read_session(engine_for(_cfg(config))) as s:
        events = get_history(s, item)
    if not events:
        typer.echo(f"no events for {item}", err=True)
        raise typer.Exit(1)
    from pipeline.review.terminal import cell

    table = Table(title=cell(f"history of {item}"))
    for col in ("at", "actor", "kind", "item", "before", "after", "model / prompt", "detail"):
        table.add_column(col, overflow="fold")
    for e in events:
        model = " / ".join(x for x in (e["model"], e["prompt_name"]) if x)
        table.add_row(*(cell(v) for v in (e["at"], e["actor"], e["kind"], e["item_id"], _short(e["before"]),
                                          _short(e["after"]), model, e["detail"])))
    Console(width=200).print(table)


def _short(d) -> str:
    return "" if d is None else json.dumps(d, ensure_ascii=False)[:300]
