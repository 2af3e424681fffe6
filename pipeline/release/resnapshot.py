"""Scenes at the reviewed failure time.

Stage 2 snapshots the scene from the *model's* onset; reviewers may move that onset. When a
final annotation's `fail_step` differs from its localization's, the release takes the scene
again from the episode's logged states (raw data, never changed) with stage 2's own rules:
the first settled step at or after the reviewed onset (`stage2.phases.settled_step`), the
same normalized BDDL, and a history window ending at the reviewed onset. The files go to
`<run>/stage3/reviewed_scenes/` (derived from reviewed labels, beside the raw data), in the
release layout, so the release copies them like stage 2's. No simulator is needed: verify
checks the result like any other scene.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.atomic import write_text, write_with
from pipeline.config import Stage2Config
from pipeline.errors import EpisodeError
from pipeline.evidence import read_evidence
from pipeline.layout import RunLayout, scene_files
from pipeline.records import Annotation, EpisodeRecord, Localization
from pipeline.stage2.history import build_history, write_history
from pipeline.stage2.layout import load_episode
from pipeline.stage2.phases import settled_step


def needs_resnapshot(ann: Annotation, loc: Localization) -> bool:
    return ann.fail_step != loc.fail_step


def resnapshot(run_dir: Path, ann: Annotation, loc: Localization, ep: EpisodeRecord,
               cfg: Stage2Config) -> tuple[Path, Path, Path | None]:
    """Write the scene pair (+ history) for the reviewed onset; return their paths.
    Raises EpisodeError (reason, detail naming the file) when the inputs cannot give one."""
    layout = RunLayout(run_dir)
    stage2 = layout.stage2.root
    episode = load_episode(layout.stage1.root, ep)
    evidence_path = layout.stage2.abs(layout.stage2.evidence(ep))
    try:
        evidence = read_evidence(evidence_path)
    except (OSError, ValueError) as e:
        raise EpisodeError("no_evidence", f"{evidence_path}: {e}") from None
    onset = min(max(ann.fail_step, 0), ep.steps)
    step = settled_step(evidence, onset, cfg.settle_speed_mps, cfg.settle_steps)
    if step is None:
        raise EpisodeError("not_settled", f"no settled state after the reviewed onset step {onset} of {ep.key}")
    scene = scene_files(layout.stage3.reviewed_scenes, ep.key, step)
    bddl, state = scene.bddl, scene.state
    # the model's scene BDDL is already normalized; the task's text does not depend on the step
    write_text(bddl, (stage2 / loc.scene_bddl).read_text())
    write_with(state, lambda p: np.save(p, np.asarray(episode.states[step], dtype=np.float64)))
    history = None
    if cfg.history_frames > 0:
        history = scene.history
        write_history(history, build_history(episode.states, episode.steps, onset, cfg.history_frames,
                                             cfg.history_stride_steps, ep.control_hz))
    return bddl, state, history
