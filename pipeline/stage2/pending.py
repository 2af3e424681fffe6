"""Stage 2's units: the failed episodes of the manifest, and the manifest rows it sets aside.

Input: `stage1/episodes.parquet`, read row by row (records.read_episode_rows). Output: the
failed EpisodeRecords (the runner skips those whose done marker still names their inputs,
layout.fingerprint). A row that makes no record becomes `quarantine/<key>.json` (reason
`stage1_bad_manifest`, file and field named) and goes away once the row reads again. Only a
manifest that cannot be read at all is fatal.
"""

from __future__ import annotations

import json
import shutil

from pipeline.atomic import write_json
from pipeline.config import Config
from pipeline.layout import RunLayout, Stage2Layout
from pipeline.errors import FatalError
from pipeline.records import EpisodeRecord, ManifestProblem, QuarantineEntry, QuarantineReason, read_episode_rows


def read_failures(cfg: Config) -> tuple[list[EpisodeRecord], int, int]:
    """(failed episodes, failed total, successes skipped). Manifest rows that make no record
    are set aside here (`stage1_bad_manifest`), the rest go on."""
    layout = RunLayout.of(cfg)
    manifest = layout.stage1.manifest
    if not manifest.exists():
        raise FatalError(f"{manifest}: no stage 1 manifest; run `recover stage1` first")
    try:
        episodes, problems = read_episode_rows(manifest)
    except Exception as e:  # the whole file unreadable (truncated): nothing to set aside row by row
        raise FatalError(f"{manifest}: unreadable stage 1 manifest ({type(e).__name__}: {e})") from None
    _set_aside_manifest_rows(layout.stage2, problems, layout.rel(manifest).as_posix())
    failed = [e for e in episodes if not e.success]
    n_success = len(episodes) - len(failed) + sum(p.success is True for p in problems)
    return failed, len(failed) + sum(p.success is not True for p in problems), n_success


def _set_aside_manifest_rows(paths: Stage2Layout, problems: list[ManifestProblem], manifest: str) -> None:
    """One quarantine entry per bad manifest row (a row whose success cell says True is no
    failure and is skipped like the other successes); entries of rows fixed since go away.
    `manifest` is the manifest's path relative to the run, as the entries name it."""
    wanted = {}
    for p in problems:
        if p.success is True:
            continue
        wanted[p.key] = QuarantineEntry(key=p.key, stage="stage2", source="stage2", reason=QuarantineReason.stage1_bad_manifest,
                                        detail=f"{manifest} row {p.row}: field {p.field}: {p.detail}",
                                        file=manifest, field=p.field).model_dump(mode="json")
    q_root = paths.quarantine_dir
    for f in sorted(q_root.rglob("*.json")) if q_root.exists() else []:
        try:
            old = json.loads(f.read_text())
        except (OSError, ValueError):
            continue
        if old.get("reason") == QuarantineReason.stage1_bad_manifest and old.get("key") not in wanted:
            f.unlink(missing_ok=True)
    for key, entry in wanted.items():
        target = paths.abs(paths.quarantine_for_key(key))
        if not target.exists() or json.loads(target.read_text()) != entry:  # a rerun rewrites nothing
            write_json(target, entry)


def forget(paths: Stage2Layout, rec: EpisodeRecord) -> None:
    """Drop what an episode's old inputs produced that the redo would not overwrite (its VLM
    answer is the VLM step's: its marker records the same inputs, `VLMStep.forget`)."""
    shutil.rmtree(paths.scene_dir(rec.key), ignore_errors=True)
