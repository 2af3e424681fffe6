"""Stage 2 for one failed episode: evidence -> onset -> phases -> scene + history -> record.

Inputs: the task's built `SimEnv`, the episode's stage-1 logs, the config and (when a VLM
backend ran) its stored outcome. Outputs, all written atomically: the evidence parquet
(always, so reviewers see it even for quarantined episodes), then EITHER a scene pair +
history + Localization JSON, OR a QuarantineEntry JSON saying why. Returns an `Outcome`.

The onset comes from the VLM when one ran (its time mapped to a step through stage 1's
frame table), else from the simstate rules; simstate always runs, and its time is kept
beside the VLM's (`simstate_time_s`) for the agreement report.
The scene pair is written at the first settled step at or after the onset (see
`phases.settled_step`); the history is the window before the onset.
Quarantine reasons from here: no_failure_found (simstate saw no event; carries the idle
fallback step), not_settled (objects never calm again), goal_satisfied_at_onset, bddl_*,
state_shape, stage1_* (bad inputs: a missing, truncated or inconsistent file, named with the
field in `file` / `field`), and a VLM parse/backend reason (truncated, no_json, schema,
out_of_range, backend_error, ...).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.atomic import write_json
from pipeline.config import Stage2Config
from pipeline.errors import EpisodeError
from pipeline.evidence import compute_evidence, write_evidence
from pipeline.labelers.base import Episode, Onset, Provenance
from pipeline.labelers.simstate.labeler import SimstateLocalizer
from pipeline.layout import Stage2Layout
from pipeline.records import EpisodeRecord, Localization, QuarantineEntry, QuarantineReason
from pipeline.stage2.history import build_history, render_frames, write_history
from pipeline.stage2.layout import load_episode
from pipeline.stage2.phases import settled_step, split_phases, step_for_time
from pipeline.stage2.scenes import write_scene

SIMSTATE = SimstateLocalizer()


@dataclass
class Outcome:
    key: str
    status: str  # scene | quarantine
    reason: str = ""
    onset_step: int | None = None
    simstate_step: int | None = None
    source: str = "simstate"
    onset_kind: str = ""


def _quarantine(paths: Stage2Layout, rec: EpisodeRecord, entry: QuarantineEntry) -> Outcome:
    paths.abs(paths.localization(rec)).unlink(missing_ok=True)
    write_json(paths.abs(paths.quarantine(rec)), entry.model_dump(mode="json"))
    return Outcome(key=rec.key, status="quarantine", reason=entry.reason, source=entry.source)


def run_relative(file: str | None, run: Path) -> str | None:
    """A file as reviewers see it: relative to the run folder when it lies inside."""
    if file is None:
        return None
    try:
        return Path(file).resolve().relative_to(Path(run).resolve()).as_posix()
    except ValueError:
        return file


def process_episode(env, rec: EpisodeRecord, stage1: Path, paths: Stage2Layout, cfg: Stage2Config,
                    vlm: Onset | None = None) -> Outcome:
    """`vlm`: None for simstate, else the VLM step's stored answer (a fail_time_s or a reason)."""
    try:
        ep = load_episode(stage1, rec)
    except EpisodeError as e:
        return _quarantine(paths, rec, QuarantineEntry(key=rec.key, stage="stage2", source="stage2",
                                                       reason=e.reason, detail=e.detail,
                                                       file=run_relative(e.file, stage1.parent), field=e.field))
    actions = ep.steps["action"]
    grip = actions[:, 6] if len(actions) else np.zeros(0)
    ev = compute_evidence(env, ep.states, grip, rec.control_hz)
    ev_rel = paths.evidence(rec)
    write_evidence(paths.abs(ev_rel), ev)
    sim = SIMSTATE.localize([Episode(rec, ep.folder, evidence=ev)])[0]  # always: events + agreement
    source = vlm.source if vlm else sim.source
    trace = (vlm or Provenance(source=source)).trace()

    def quarantine(reason: QuarantineReason | str, detail: str, **extra) -> Outcome:
        entry = QuarantineEntry(key=rec.key, stage="stage2", source=source, reason=reason, detail=detail,
                                events=sim.events, evidence=str(ev_rel), **trace, **extra)
        return _quarantine(paths, rec, entry)

    if vlm is not None and not vlm.found:
        return quarantine(vlm.reason or QuarantineReason.backend_error, vlm.detail)
    if vlm is not None:
        onset = step_for_time(vlm.fail_time_s, ep.frames, rec.steps, rec.control_hz)
    elif sim.fail_step is not None:
        onset = sim.fail_step
    else:
        fb = sim.fallback_step
        return quarantine(QuarantineReason.no_failure_found,
                          f"simstate saw no failure event; the robot was idle from step {fb} "
                          f"({fb / rec.control_hz:.1f} s), a fallback onset for review",
                          fallback_step=fb, fallback_time_s=fb / rec.control_hz)
    onset = min(onset, rec.steps)
    scene_step = settled_step(ev, onset, cfg.settle_speed_mps, cfg.settle_steps)
    if scene_step is None:
        return quarantine(QuarantineReason.not_settled, f"objects never stayed below {cfg.settle_speed_mps} m/s for "
                          f"{cfg.settle_steps} steps after the onset (step {onset}): no restorable scene")
    try:
        bddl, npy = write_scene(paths.root, env, rec.suite, rec.task, rec.episode_id, scene_step,
                                ep.states[scene_step])
    except EpisodeError as e:
        return quarantine(e.reason, e.detail)
    history_rel = None
    if cfg.history_frames > 0:
        hist = build_history(ep.states, ep.steps, onset, cfg.history_frames, cfg.history_stride_steps,
                             rec.control_hz)
        frames = render_frames(env, hist, list(cfg.history_cameras), cfg.history_resolution)
        scene = paths.scene(rec.key, scene_step)
        hist_path = scene.history
        write_history(hist_path, hist)
        write_history(scene.history_frames, frames)
        history_rel = str(hist_path.relative_to(paths.root))
    loc = Localization(
        key=rec.key, suite=rec.suite, task=rec.task, episode_id=rec.episode_id, instruction=rec.instruction,
        source=source, **trace, fail_step=onset, scene_step=scene_step,
        fail_time_s=vlm.fail_time_s if vlm else round(onset / rec.control_hz, 3),
        phases=split_phases(ev, onset, cfg.settle_speed_mps, cfg.settle_steps),
        scene_bddl=str(bddl.relative_to(paths.root)), scene_state=str(npy.relative_to(paths.root)),
        history=history_rel, events=sim.events, evidence=str(ev_rel),
        simstate_time_s=sim.fail_time_s,
    )
    paths.abs(paths.quarantine(rec)).unlink(missing_ok=True)
    write_json(paths.abs(paths.localization(rec)), loc.model_dump(mode="json"))
    onset_event = next((e for e in sim.events if e.step == sim.fail_step), None)
    kind = onset_event.kind if (vlm is None and onset_event) else ""
    return Outcome(key=rec.key, status="scene", onset_step=onset, simstate_step=sim.fail_step, source=source,
                   onset_kind=kind)
