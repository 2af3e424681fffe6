"""Ground truth of a failed episode, derived from the scripted generator's own record.

Input: an episode's `truth.parquet` (`pipeline.policies.scripted.truth.TRUTH_SCHEMA`: one
row per skill attempt, with its outcome, decisive event and the scene change after it).
Output: an `EpisodeTruth`: onset step and time, expected category and recovery level.
Only episodes that failed have a truth; the openpi generator writes no record, and nothing
else in the pipeline reads one.

Rules:
- Attempt: the first attempt (in execution order) whose outcome is not `achieved`. Later
  attempts are retries or other subgoals; the label describes the first thing that went
  wrong. No such attempt (every attempt achieved its subgoal, the goal fell apart later, or
  the episode ended before the next skill started) -> no truth, reason `no_failed_attempt`;
  a first failed attempt that only ran out of time made no mistake to localize -> no
  truth, reason `timeout`. Both are counted in the benchmark's set-aside reasons.
- Onset: that attempt's decisive event step (its meaning per outcome is in the record's
  module docstring): the gripper closing off target (missed_grasp), the state the object
  left the closed hand (lost_grasp), the opening that released it (dropped, misplaced), the
  first motion of the object the contact displaced (knocked, event `knock`) or the first
  state in which a goal conjunct that held stopped holding (knocked, event `undo`: a drawer
  bumped shut), the hand letting go of a part left half open / a knob not turned
  (half_open, not_turned).
- Category (the project's six, `records.Category`):
  missed_grasp, lost_grasp                  -> grasp_failure
  dropped                                   -> grasp_failure if released in transit (the
                                               attempt's phase at the release is a lift or a
                                               transport) farther than PLACE_NEAR_M (xy)
                                               from the reference, else placement_failure
                                               (released while placing: lowering, opening)
  misplaced                                 -> placement_failure
  knocked                                   -> object_displacement if the displaced object
                                               is a goal target, else
                                               collision_or_interaction_failure (also an
                                               undone part: the drawer is no target)
  half_open, not_turned                     -> collision_or_interaction_failure
  anything else                             -> other
  (environmental_obstruction is never expected: the generator does not know when a
  fixture blocked it.)
- Level: the taxonomy (annotations/README.md) applied to the privileged scene change from
  the onset to the scene the failure leaves: the end of that attempt (`changes`, the
  generator's record), or, when stage 2's evidence shows the objects still moving then,
  the first settled state at or after the onset (`stage2.phases.settled_step`, stage 2's
  own rule for the scene it releases; the change measured on the evidence,
  `scene_changes`). A mug still tipping over when the generator's attempt ended is an L3
  scene, not an L2 one. Without evidence (no stage 2 yet) the attempt's end; the truth
  says which (`level_window`). First rule that matches:
  L4 environmental recovery: an object that is neither a goal target nor a reference moved
     >= MOVED_M (or toppled) and ends within OBSTRUCT_M (xy) of a target or reference;
  L3 object state recovery: a goal target toppled (tilt >= TOPPLE_DEG), fell off the table,
     or moved >= FAR_M and is not held;
  L2 action adaptation: any object moved >= MOVED_M or tilted >= TILT_DEG more;
  L1 action retry: nothing changed (a missed grasp, a knob not turned).
  The thresholds are the taxonomy's, fixed here on purpose: tuning the simstate rules
  must not move the truth they are scored against.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.config import Stage2Config
from pipeline.evidence import Evidence, goal_roles, read_evidence
from pipeline.records import Category, Level, Record
from pipeline.stage2.phases import settled_step

MOVED_M, FAR_M, OBSTRUCT_M, PLACE_NEAR_M = 0.01, 0.05, 0.15, 0.10
TRANSIT_PHASES = frozenset({"pick_lift", "lift", "transport"})  # carrying, not yet placing
TILT_DEG, TOPPLE_DEG = 10.0, 45.0
_REQUIRED = ("attempt", "outcome", "event_step", "target", "changes", "knocked")


class EpisodeTruth(Record):
    key: str
    onset_step: int
    onset_time_s: float
    category: str  # a records.Category value
    level: str  # a records.Level value
    outcome: str  # outcome of the first failed attempt
    attempt: int
    skill: str
    event: str
    event_object: str | None = None
    detail: str = ""
    level_window: str = "attempt"  # "attempt" (the generator's record) or "scene" (evidence, to the settled state)
    level_end_step: int | None = None  # the state the level's change was measured at


class TruthError(ValueError):
    """An unusable truth record; `reason` is counted, the message names the file."""

    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


def read_truth(path: str | Path) -> tuple[list[dict], dict]:
    """Rows (in attempt order) and metadata of a truth.parquet; TruthError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise TruthError("no_truth", f"{path}: no such file (only the scripted generator writes one)")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as e:  # truncated or not parquet (ArrowInvalid, ArrowIOError): one bad input
        raise TruthError("bad_truth", f"{path}: not a parquet file ({type(e).__name__}: {e})") from None
    missing = [c for c in _REQUIRED if c not in table.column_names]
    if missing:
        raise TruthError("bad_truth", f"{path}: missing column(s) {missing}")
    raw = (table.schema.metadata or {}).get(b"truth")
    meta = json.loads(raw) if raw else {}
    if meta.get("error"):
        raise TruthError("truth_error", f"{path}: the generator's recording failed: {meta['error']}")
    return sorted(table.to_pylist(), key=lambda r: r["attempt"]), meta


def phase_at(row: dict, step: int | None) -> str | None:
    """The label of the attempt's phase running at `step`."""
    if step is None:
        return None
    began = [p for p in row.get("phases") or [] if p["step"] <= step]
    return began[-1]["label"] if began else None


def category_of(row: dict, targets: list[str]) -> Category:
    o = row["outcome"]
    if o in ("missed_grasp", "lost_grasp"):
        return Category.grasp_failure
    if o == "dropped":
        # the generator opens its hand only to place: an early or high release while lowering
        # over the place is a placement failure however far the place was off (watched:
        # bowls released 10.1-11.3 cm from the plate while lowering were called drops in transit)
        d = row.get("release_dist_m")
        in_transit = phase_at(row, row.get("event_step")) in TRANSIT_PHASES
        near = d is not None and d <= PLACE_NEAR_M
        return Category.grasp_failure if in_transit and not near else Category.placement_failure
    if o == "misplaced":
        return Category.placement_failure
    if o == "knocked":
        return Category.object_displacement if row.get("event_object") in targets else \
            Category.collision_or_interaction_failure
    if o in ("half_open", "not_turned"):
        return Category.collision_or_interaction_failure
    return Category.other


def level_of(changes: list[dict], targets: list[str], references: list[str]) -> Level:
    ch = {c["object"]: c for c in changes}
    focus = [o for o in targets + references if o in ch]
    for o, c in ch.items():
        if o in targets or o in references:
            continue
        toppled = c["tilt_deg"] >= TOPPLE_DEG > c["tilt_deg"] - c["tilt_gain_deg"]
        if c["moved_m"] >= MOVED_M or toppled:
            xy = np.asarray(c["position"][:2])
            if any(np.linalg.norm(xy - np.asarray(ch[f]["position"][:2])) <= OBSTRUCT_M for f in focus):
                return Level.L4
    for o in targets:
        c = ch.get(o)
        if c and (c["tilt_deg"] >= TOPPLE_DEG or c["fell_off"] or (c["moved_m"] >= FAR_M and not c["held"])):
            return Level.L3
    if any(c["moved_m"] >= MOVED_M or c["tilt_gain_deg"] >= TILT_DEG for c in changes):
        return Level.L2
    return Level.L1


def settle_of(stage2: Stage2Config) -> tuple[float, int]:
    """Stage 2's settle rule (speed, calm steps): the truth's scene window reads it too."""
    return stage2.settle_speed_mps, stage2.settle_steps


SETTLE = settle_of(Stage2Config())  # its defaults, where no run config is at hand (the review's truth view)


def scene_changes(ev: Evidence, onset: int, scene: int) -> list[dict]:
    """The generator's `changes` (one per object, truth.TRUTH_SCHEMA's fields) measured on
    the evidence from state `onset` to state `scene`: tilt against the first state, fell off
    = 10 cm below where it started, held = in the hand at `scene`."""
    out = []
    for o in ev.objects:
        pos, tilt = ev.col("position", o), ev.col("tilt_deg", o)
        out.append({"object": o, "moved_m": float(np.linalg.norm(pos[scene] - pos[onset])),
                    "tilt_deg": float(tilt[scene]), "tilt_gain_deg": float(tilt[scene] - tilt[onset]),
                    "fell_off": bool(ev.col("lift", o)[scene] < -0.1), "held": ev.grasped[scene] == o,
                    "position": [float(v) for v in pos[scene]]})
    return out


def _window(row: dict, step: int, ev: Evidence | None, settle: tuple[float, int]) -> tuple[list[dict], str, int]:
    """The change the level is read from, its window's name and the state it ends at (rules above)."""
    from pipeline.policies.scripted.truth import FALL_ROWS  # here: the policies package loads the generator

    recorded = int(row["end_step"]) if row.get("end_step") is not None else step
    end = max(recorded, step + FALL_ROWS)  # the generator's own window (truth.rows)
    if ev is not None:
        end = min(end, len(ev) - 1)
        scene = settled_step(ev, min(step, len(ev) - 1), *settle)
        if scene is not None and scene > end:
            return scene_changes(ev, step, scene), "scene", scene
    return row["changes"] or [], "attempt", end


def derive(key: str, rows: list[dict], meta: dict, control_hz: int = 20, evidence: Evidence | None = None,
           settle: tuple[float, int] = SETTLE) -> EpisodeTruth:
    """The truth of one failed episode from its attempt rows (TruthError when there is none);
    with the episode's `evidence` the level's window reaches the settled scene (`settle`:
    stage 2's speed and calm steps)."""
    failed = [r for r in rows if r["outcome"] != "achieved"]
    if not failed:
        raise TruthError("no_failed_attempt", f"{key}: every recorded attempt achieved its subgoal")
    row = failed[0]
    if row["outcome"] == "timeout":
        raise TruthError("timeout", f"{key}: attempt {row['attempt']} ran out of time without a mistake: "
                                    "no onset to score")
    if row["event_step"] is None:
        raise TruthError("no_event", f"{key}: attempt {row['attempt']} ({row['outcome']}) has no decisive step")
    goal = meta.get("goal") or []
    known = list(meta.get("objects", [])) + list(meta.get("fixtures", []))
    targets, refs = goal_roles(goal, known)
    step = int(row["event_step"])
    changes, window, end = _window(row, step, evidence, settle)
    return EpisodeTruth(
        key=key, onset_step=step, onset_time_s=round(step / control_hz, 3),
        category=category_of(row, targets).value, level=level_of(changes, targets, refs).value,
        outcome=row["outcome"], attempt=int(row["attempt"]), skill=row["skill"], event=row["event"],
        event_object=row.get("event_object"), detail=row.get("detail") or "", level_window=window,
        level_end_step=end,
    )


def episode_truth(path: str | Path, key: str, control_hz: int = 20, evidence_path: str | Path | None = None,
                  settle: tuple[float, int] = SETTLE) -> EpisodeTruth:
    """The truth of the episode whose record is `path`; with stage 2's evidence file
    (`evidence_path`, when it exists and reads) the level's window reaches the scene."""
    rows, meta = read_truth(path)
    ev = None
    if evidence_path is not None and Path(evidence_path).is_file():
        try:
            ev = read_evidence(evidence_path)
        except (pa.ArrowException, OSError, ValueError, KeyError):
            ev = None  # unreadable: the attempt's window, which `level_window` says
    return derive(key, rows, meta, control_hz, ev, settle)
