"""The stage 1 manifest and its summary table.

Inputs: the done markers under `stage1/_done/` (each holds one EpisodeRecord as JSON).
Outputs: `stage1/episodes.parquet` (EPISODE_SCHEMA, sorted by episode key, rebuilt from
the markers so it is complete after any crash and rerun), a rich summary table, and
`stage1/summary.json`.

Invariants: one manifest row per done marker of a planned unit; no key twice.
"""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow.parquet as pq
from rich.table import Table

from pipeline.atomic import write_json, write_with
from pipeline.errors import InputError, invalid_file
from pipeline.layout import Stage1Layout
from pipeline.records import EpisodeRecord, episodes_table


def _record(marker: Path) -> EpisodeRecord:
    try:
        return EpisodeRecord.model_validate(json.loads(marker.read_text()))
    except (ValueError, OSError) as e:  # ValidationError and JSONDecodeError are ValueErrors
        raise invalid_file(marker, e) from e


def collect_records(stage1_dir: Path, unit_ids: list[str] | None = None) -> list[EpisodeRecord]:
    """EpisodeRecords of the done units (of `unit_ids`, or all), sorted by key."""
    from pipeline.runner.runner import marker_files

    files = marker_files(stage1_dir, unit_ids)
    records = [_record(f) for f in files.values()]
    records.sort(key=lambda r: r.key)
    keys = [r.key for r in records]
    if len(set(keys)) != len(keys):
        twice = sorted({k for k in keys if keys.count(k) > 1})
        raise InputError(next(iter(files.values())).parent, "key", f"episode keys {twice[:5]} appear in more than one done marker")
    return records


def write_manifest(stage1_dir: Path, records: list[EpisodeRecord]) -> Path:
    path = Stage1Layout(Path(stage1_dir)).manifest
    table = episodes_table(records)
    write_with(path, lambda p: pq.write_table(table, p))
    return path


def summarize(records: list[EpisodeRecord]) -> list[dict]:
    """Per suite/task: episodes, successes, failures, mean steps; plus an 'all' row."""
    groups: dict[tuple[str, str], list[EpisodeRecord]] = {}
    for r in records:
        groups.setdefault((r.suite, r.task), []).append(r)
    groups[("all", "")] = list(records)
    rows = []
    for (suite, task), rs in groups.items():
        n = len(rs)
        ok = sum(r.success for r in rs)
        rows.append(
            {
                "suite": suite,
                "task": task,
                "episodes": n,
                "successes": ok,
                "failures": n - ok,
                "mean_steps": round(sum(r.steps for r in rs) / n, 1) if n else 0.0,
            }
        )
    return rows


def summary_table(rows: list[dict]) -> Table:
    table = Table(title="stage 1 summary")
    for col in ("suite", "task", "episodes", "successes", "failures", "mean steps"):
        table.add_column(col, justify="left" if col in ("suite", "task") else "right", overflow="fold")
    for r in rows:
        style = "bold" if r["suite"] == "all" else None
        table.add_row(
            r["suite"], r["task"], str(r["episodes"]), str(r["successes"]), str(r["failures"]), f"{r['mean_steps']:.1f}",
            style=style,
        )
    return table


def write_summary(stage1_dir: Path, rows: list[dict], extra: dict) -> None:
    write_json(Stage1Layout(Path(stage1_dir)).summary, {"tasks": rows, **extra})
