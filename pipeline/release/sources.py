"""Gather what a release is made of: final reviewed annotations joined with their scenes.

Inputs (run folder): `stage3/annotations/<suite>/<task>/episode_<id>.json` (`records.Annotation`:
final reviewed annotations, the review export), `stage2/localizations/<suite>/<task>/<episode_id>.json`
(`Localization`, with the stage-2-relative paths of the scene pair and history), and
`stage1/episodes.parquet` (`EpisodeRecord`: policy, seed, init state).
When reviewers moved the failure onset, the scene is taken again at the reviewed time
(`resnapshot.py`). Output: `ReleaseItem`s sorted by key, and `QuarantineEntry`s for annotations that cannot be
released (unreadable, or a missing localization, episode or scene file), with the reason.
Only annotations are released: an episode without a final annotation never appears.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

from pydantic import ValidationError

from pipeline.config import Stage2Config
from pipeline.errors import EpisodeError
from pipeline.layout import RunLayout, Stage3Layout, episode_key
from pipeline.records import Annotation, EpisodeRecord, Localization, QuarantineEntry, QuarantineReason, read_episodes
from pipeline.release.resnapshot import needs_resnapshot, resnapshot


@dataclass
class ReleaseItem:
    annotation: Annotation
    localization: Localization
    episode: EpisodeRecord
    scene_bddl: Path  # absolute, in the run's stage2 folder
    scene_state: Path
    history: Path | None
    step: int

    @property
    def suite(self) -> str:
        return self.episode.suite


def _step_of(bddl: Path, fallback: int) -> int:
    m = re.fullmatch(r"step_(\d+)\.bddl", bddl.name)
    return int(m.group(1)) if m else fallback


def gather(run_dir: Path, stage2_cfg: Stage2Config | None = None) -> tuple[list[ReleaseItem], list[QuarantineEntry]]:
    """`stage2_cfg` (settle rules, history window) enables re-snapshots at reviewed onsets."""
    layout = RunLayout(run_dir)
    stage2 = layout.stage2.root
    ann_root = layout.stage3.annotations
    episodes_file = layout.stage1.manifest
    episodes = {e.key: e for e in read_episodes(episodes_file)} if episodes_file.exists() else {}
    items, skipped = [], []

    def skip(key: str, reason: QuarantineReason, detail: str) -> None:
        skipped.append(QuarantineEntry(key=key, stage="release", source="review_export", reason=reason, detail=detail))

    for path in sorted(ann_root.glob(Stage3Layout.ANNOTATION_GLOB)):
        rel = path.relative_to(run_dir)
        try:
            ann = Annotation.model_validate(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError, ValidationError) as e:
            skip(str(rel), QuarantineReason.schema, f"{path}: {e}")
            continue
        loc_path = layout.stage2.localization_of_key(episode_key(ann.suite, ann.task, ann.episode_id))
        if not loc_path.is_file():
            skip(ann.key, QuarantineReason.no_localization, f"{loc_path} missing (annotation {path})")
            continue
        try:
            loc = Localization.model_validate_json(loc_path.read_text())
        except (OSError, ValidationError) as e:
            skip(ann.key, QuarantineReason.schema, f"{loc_path}: {e}")
            continue
        ep = episodes.get(ann.key)
        if ep is None:
            skip(ann.key, QuarantineReason.no_episode, f"{episodes_file} has no episode {ann.key}")
            continue
        if stage2_cfg is not None and needs_resnapshot(ann, loc):
            try:  # reviewers moved the onset: the scene is taken again at the reviewed time
                bddl, state, history = resnapshot(run_dir, ann, loc, ep, stage2_cfg)
            except EpisodeError as e:
                skip(ann.key, e.reason, e.detail)
                continue
        else:
            # the annotation names the snapshot its reviewers saw; older exports leave it to stage 2
            bddl = stage2 / (ann.scene_bddl or loc.scene_bddl)
            state = stage2 / (ann.scene_state or loc.scene_state)
            history = stage2 / loc.history if loc.history else None
        missing = [str(p) for p in (bddl, state, history) if p is not None and not p.exists()]
        if missing:
            skip(ann.key, QuarantineReason.missing_scene_file, ", ".join(missing))
            continue
        items.append(ReleaseItem(ann, loc, ep, bddl, state, history, _step_of(bddl, loc.fail_step)))
    items.sort(key=lambda it: (it.episode.suite, it.episode.task, it.episode.episode_id))
    return items, skipped
