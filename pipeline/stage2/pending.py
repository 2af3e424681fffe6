"""Which failed episodes stage 2 still has to do, and the manifest rows it sets aside.

Input: `stage1/episodes.parquet`, read row by row (records.read_episode_rows), and the done
markers under `stage2/_done/`. Output: the failed EpisodeRecords to (re)do. A marker counts
only while the episode's inputs are what it recorded (layout.fingerprint: size + mtime of the
stage-1 files, a hash of the manifest row); a marker from before fingerprints counts as done.
A row that makes no record becomes `quarantine/<key>.json` (reason `stage1_bad_manifest`,
file and field named) and goes away once the row reads again. Only a manifest that cannot be
read at all is fatal.
"""

from __future__ import annotations

import json
import shutil

from pipeline.atomic import Completions, write_json
from pipeline.config import Config
from pipeline.layout import RunLayout, Stage2Layout
from pipeline.errors import FatalError
from pipeline.records import EpisodeRecord, ManifestProblem, QuarantineEntry, QuarantineReason, read_episode_rows
from pipeline.stage2.layout import fingerprint, unit_id


def pending_failures(cfg: Config, paths: Stage2Layout) -> tuple[list[EpisodeRecord], int, int]:
    """(failed episodes not yet done, failed total, successes skipped). A failed episode is
    done when its marker exists and names the inputs it has now (layout.fingerprint); markers
    written before fingerprints existed count as done. Manifest rows that make no record are
    set aside here (`stage1_bad_manifest`), the rest go on."""
    layout = RunLayout.of(cfg)
    manifest = layout.stage1.manifest
    if not manifest.exists():
        raise FatalError(f"{manifest}: no stage 1 manifest; run `recover stage1` first")
    try:
        episodes, problems = read_episode_rows(manifest)
    except Exception as e:  # the whole file unreadable (truncated): nothing to set aside row by row
        raise FatalError(f"{manifest}: unreadable stage 1 manifest ({type(e).__name__}: {e})") from None
    _set_aside_manifest_rows(paths, problems, layout.rel(manifest).as_posix())
    failed = [e for e in episodes if not e.success]
    done = Completions(paths.root)
    done_ids = done.done_ids()
    todo = []
    for e in failed:
        if unit_id(e) in done_ids:
            recorded = (done.info(unit_id(e)) or {}).get("inputs")
            if recorded is None or recorded == fingerprint(layout.stage1.root, e):
                continue
            _forget(paths, e)  # its inputs changed since: the stored answers are about old files
        todo.append(e)
    n_success = len(episodes) - len(failed) + sum(p.success is True for p in problems)
    return todo, len(failed) + sum(p.success is not True for p in problems), n_success


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


def _forget(paths: Stage2Layout, rec: EpisodeRecord) -> None:
    """Drop what an episode's old inputs produced that the redo would not overwrite."""
    paths.abs(paths.vlm(rec)).unlink(missing_ok=True)  # the VLM is asked again about the new video
    shutil.rmtree(paths.scene_dir(rec.key), ignore_errors=True)
