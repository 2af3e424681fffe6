"""The scripted generator's own record of what it did: one row per skill attempt.

Inputs: the skills call `begin` / `note` / `end` as they go (at the simulator step the
policy is at), the policy marks each primitive it starts (`mark`) and watches every
executed step (`watch`: gripper command, held object, object poses, all read from
privileged state). Output: `table()`, a `TRUTH_SCHEMA` table written by stage 1 as
`truth.parquet` beside `steps.parquet`.

Per attempt: the skill and its objects, the steps it spanned, the noise actually applied,
and the outcome the expert judges from privileged state (`Outcome`), plus the step and
kind of its decisive event:
- missed_grasp: the fingers closed and the target is not in hand; event `close`, the first
  gripper-close command after the descent began.
- lost_grasp: the target left the hand while the gripper was still commanded closed;
  event `slip`, the first state without it in hand.
- dropped: the target left the hand because the gripper opened before the release point
  (an early opening in transport or while lowering); event `release`, that open command.
- misplaced: released at the planned height but the conjunct does not hold; event
  `release`, the first open command after lowering began.
- knocked: an object was displaced >= KNOCK_M by contact before the attempt's own failure
  event (or, in an attempt that achieved its subgoal, a goal object >= KNOCK_M or any
  object >= FAR_KNOCK_M); event `knock`, the first state it had moved >= MOTION_M.
- half_open / not_turned: a drawer/door/knob attempt ended without its conjunct; event
  `let_go`, the step the hand stopped operating the part.
- timeout: the episode ended inside the attempt; event `timeout`, the attempt's start.
Also per attempt, the scene change from the decisive event to the attempt's end (per
object: moved, tilt, tilt gain, fell off, held, position), which `pipeline.truth.derive`
turns into a recovery level. Recording only reads the simulator: actions and the noise
stream are exactly those of an unrecorded run.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa

from pipeline import SCHEMA_VERSION

KNOCK_M = 0.02  # displacement by contact that counts as knocking an object
FAR_KNOCK_M = 0.05  # ... for an object the goal does not involve, in an achieved attempt
MOTION_M = 0.003  # first motion of a knocked object (its onset)
OUTCOMES = ("achieved", "missed_grasp", "lost_grasp", "dropped", "misplaced", "knocked", "half_open",
            "not_turned", "timeout")

_CHANGE = pa.struct([
    pa.field("object", pa.string()), pa.field("moved_m", pa.float32()), pa.field("tilt_deg", pa.float32()),
    pa.field("tilt_gain_deg", pa.float32()), pa.field("fell_off", pa.bool_()), pa.field("held", pa.bool_()),
    pa.field("position", pa.list_(pa.float32())),
])
TRUTH_SCHEMA = pa.schema(
    [
        pa.field("attempt", pa.int32(), nullable=False),
        pa.field("skill", pa.string(), nullable=False),  # pick_place | open | close | turn_on | turn_off
        pa.field("conjunct", pa.string(), nullable=False),  # e.g. "on akita_black_bowl_1 plate_1"
        pa.field("target", pa.string(), nullable=False),  # object moved, or part operated
        pa.field("reference", pa.string()),  # where it goes (pick_place)
        pa.field("start_step", pa.int32(), nullable=False),
        pa.field("end_step", pa.int32(), nullable=False),  # exclusive
        pa.field("phases", pa.list_(pa.struct([pa.field("label", pa.string()), pa.field("step", pa.int32())]))),
        pa.field("grasp_offset_m", pa.list_(pa.float32())),  # xy noise on the grasp point
        pa.field("approach_height_m", pa.float32()),  # z noise on the grasp point
        pa.field("grasp_timing_steps", pa.int32()),  # < 0 closes early, > 0 late
        pa.field("release_timing_steps", pa.int32()),
        pa.field("place_offset_m", pa.list_(pa.float32())),  # xy + release height noise
        pa.field("action_noise", pa.float32(), nullable=False),  # per-step action noise scale
        pa.field("speed_factor", pa.float32(), nullable=False),
        pa.field("subgoal_achieved", pa.bool_(), nullable=False),
        pa.field("outcome", pa.string(), nullable=False),  # one of OUTCOMES
        pa.field("event", pa.string()),  # close | slip | release | knock | let_go | timeout
        pa.field("event_step", pa.int32()),
        pa.field("event_object", pa.string()),
        pa.field("grip_error_m", pa.float32()),  # grip site to the target's body at the close
        pa.field("release_dist_m", pa.float32()),  # target to reference, xy, at the release
        pa.field("knocked", pa.list_(pa.struct([pa.field("object", pa.string()), pa.field("moved_m", pa.float32()),
                                                pa.field("step", pa.int32())]))),
        pa.field("changes", pa.list_(_CHANGE)),  # decisive event -> attempt end
        pa.field("detail", pa.string(), nullable=False),
    ],
    metadata={"schema_version": str(SCHEMA_VERSION)},
)


def _tilt(q0: np.ndarray, q: np.ndarray) -> float:
    def up(w, x, y, z):
        return np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])

    return float(np.degrees(np.arccos(np.clip(np.dot(up(*q0), up(*q)), -1.0, 1.0))))


@dataclass
class Attempt:
    index: int
    skill: str
    conjunct: tuple[str, ...]
    target: str
    reference: str | None
    start: int
    reference_xy: np.ndarray | None = None
    end: int | None = None
    outcome: str = "timeout"
    phases: list[tuple[str, int]] = field(default_factory=list)
    noise: dict = field(default_factory=dict)
    detail: str = ""


class TruthLog:
    """Attempts and a per-step privileged trace of one episode (see the module docstring)."""

    def __init__(self, scene, action_noise: float, speed: float):
        self.scene = scene
        self.action_noise, self.speed = float(action_noise), float(speed)
        self.attempts: list[Attempt] = []
        self.step = 0  # the step the policy is at (set before each skill resumes)
        env = scene.env
        self.objects = list(env.object_names)
        self.goal_objects = {a for c in env.goal for a in c[1:]}
        self.cmd: list[float] = []  # gripper command of step t
        self.held: list[str] = []  # held object in state row t
        self.pos: list[np.ndarray] = []  # (n_objects, 3) in state row t
        self.quat: list[np.ndarray] = []
        self.eef: list[np.ndarray] = []  # grip site in state row t
        self._sample()

    # ---- per step -------------------------------------------------------------------------
    def _sample(self) -> None:
        poses = self.scene.env.object_poses()
        self.pos.append(np.array([poses[o][0] for o in self.objects]).reshape(-1, 3))
        self.quat.append(np.array([poses[o][1] for o in self.objects]).reshape(-1, 4))
        self.held.append(self.scene.holding_any() or "")
        self.eef.append(np.array(self.scene.eef()))

    def watch(self, step: int, action: np.ndarray) -> None:
        """After action `step` was applied: record it and the state it led to (row step + 1)."""
        if step != len(self.cmd):
            return  # not the episode this log began with (e.g. a runner that skipped a step)
        self.cmd.append(float(action[6]))
        self._sample()

    # ---- called by skills and the policy ------------------------------------------------
    def begin(self, skill: str, conjunct: tuple[str, ...], target: str, reference: str | None = None) -> None:
        self._close_open(self.step)
        ref_xy = None
        if reference is not None:
            ref_xy = self.scene.pos(reference)[:2].copy()
        self.attempts.append(Attempt(len(self.attempts), skill, tuple(conjunct), target, reference, self.step, ref_xy))

    def note(self, **noise) -> None:
        if self.attempts and self.attempts[-1].end is None:
            self.attempts[-1].noise.update(noise)

    def mark(self, label: str) -> None:
        if self.attempts and self.attempts[-1].end is None:
            self.attempts[-1].phases.append((label, self.step))

    def end(self, outcome: str, detail: str = "") -> None:
        if outcome not in OUTCOMES:
            raise ValueError(f"outcome {outcome!r} is not one of {OUTCOMES}")
        if self.attempts and self.attempts[-1].end is None:
            a = self.attempts[-1]
            a.end, a.outcome, a.detail = self.step, outcome, detail

    def left_hand(self, obj: str) -> str:
        """Why `obj` is no longer in hand: `lost_grasp` if it went while the gripper was
        commanded closed, `dropped` if the gripper had been commanded open."""
        rows = [t for t, h in enumerate(self.held) if h == obj]
        if not rows or rows[-1] >= len(self.cmd):
            return "lost_grasp"
        return "lost_grasp" if self.cmd[rows[-1]] > 0 else "dropped"

    def judge_place(self, obj: str, satisfied: bool) -> str:
        """After a place: achieved, dropped (out of the hand before the planned release
        began) or misplaced (released as planned, at the wrong place)."""
        if satisfied:
            return "achieved"
        a = self.attempts[-1] if self.attempts else None
        opened = self._first("open", a) if a is not None else None
        if opened is not None and a is not None:
            gone = [t for t in range(a.start, min(opened, len(self.held) - 1) + 1)
                    if self.held[t] != obj and any(self.held[u] == obj for u in range(a.start, t))]
            if gone:
                return "dropped"
        return "misplaced"

    def _close_open(self, step: int) -> None:
        if self.attempts and self.attempts[-1].end is None:
            self.attempts[-1].end = step  # an attempt that stopped without a verdict: timeout

    # ---- derived from the trace ---------------------------------------------------------
    def _first(self, label: str, a: Attempt) -> int | None:
        return next((s for lab, s in a.phases if lab == label), None)

    def _held_by_row(self, a: Attempt, end: int) -> np.ndarray:
        return np.array([self.held[t] == a.target for t in range(a.start, end + 1)])

    def _event(self, a: Attempt, end: int) -> tuple[str | None, int | None, str | None]:
        cmd = np.array(self.cmd[a.start:end]) if end > a.start else np.zeros(0)
        closed = cmd > 0

        def first_after(mask: np.ndarray, step: int | None) -> int | None:
            lo = max((step if step is not None else a.start) - a.start, 0)
            hits = np.flatnonzero(mask[lo:])
            return int(hits[0]) + lo + a.start if len(hits) else None

        held = self._held_by_row(a, end)
        o = a.outcome
        if o == "missed_grasp":
            return "close", first_after(closed, self._first("descend", a)), a.target
        if o in ("lost_grasp", "dropped"):
            was = np.flatnonzero(held)
            if len(was):
                gone = np.flatnonzero(~held[was[0]:])
                row = int(gone[0]) + int(was[0]) + a.start if len(gone) else None
                if o == "dropped" and row is not None:
                    opens = np.flatnonzero(~closed[: row - a.start])
                    row = int(opens[-1]) + a.start if len(opens) else row
                    # the open command that began the release: the first of its run
                    while row > a.start and not closed[row - 1 - a.start]:
                        row -= 1
                return ("slip" if o == "lost_grasp" else "release"), row, a.target
            return ("slip" if o == "lost_grasp" else "release"), None, a.target
        if o == "misplaced":
            return "release", first_after(~closed, self._first("lower", a)), a.target
        if o in ("half_open", "not_turned"):
            steps = [s for lab, s in a.phases if lab in ("let_go", "back_off", "retreat")]
            return "let_go", (min(steps) if steps else a.start), a.target
        if o == "timeout":
            return "timeout", a.start, a.target
        return None, None, None

    def _knocks(self, a: Attempt, end: int) -> list[dict]:
        """Objects other than the held target that moved >= KNOCK_M in the attempt."""
        out = []
        p0 = self.pos[a.start]
        held = self._held_by_row(a, end)
        first_held = int(np.flatnonzero(held)[0]) + a.start if held.any() else end + 1
        for i, o in enumerate(self.objects):
            stop = min(end, first_held) if o == a.target else end  # the target counts until grasped
            track = np.array([np.linalg.norm(self.pos[t][i] - p0[i]) for t in range(a.start, stop + 1)])
            if len(track) and track.max() >= KNOCK_M:
                moving = np.flatnonzero(track >= MOTION_M)
                out.append({"object": o, "moved_m": float(track.max()), "step": int(moving[0]) + a.start})
        return out

    def _changes(self, a_row: int, b_row: int) -> list[dict]:
        out = []
        table = self.scene.table_height() if hasattr(self.scene, "table_height") else None
        for i, o in enumerate(self.objects):
            t0 = _tilt(self.quat[0][i], self.quat[a_row][i])
            t1 = _tilt(self.quat[0][i], self.quat[b_row][i])
            fell = bool(self.pos[b_row][i][2] < self.pos[0][i][2] - 0.1) if table is not None else False
            out.append({"object": o, "moved_m": float(np.linalg.norm(self.pos[b_row][i] - self.pos[a_row][i])),
                        "tilt_deg": t1, "tilt_gain_deg": t1 - t0, "fell_off": fell,
                        "held": self.held[b_row] == o, "position": self.pos[b_row][i].astype(np.float32).tolist()})
        return out

    def rows(self) -> list[dict]:
        last = len(self.cmd)  # state rows run 0 .. last
        out = []
        for a in self.attempts:
            end = min(a.end if a.end is not None else last, last)
            if a.end is None or a.end > last:
                a.outcome = "timeout"
            achieved = a.outcome == "achieved"
            kind, step, obj = self._event(a, end)
            knocks = self._knocks(a, end)
            idx = {o: i for i, o in enumerate(self.objects)}
            if knocks:
                k = min(knocks, key=lambda d: d["step"])
                counts = (k["step"] < step) if step is not None else not achieved
                if achieved:
                    big = [d for d in knocks if d["object"] in self.goal_objects or d["moved_m"] >= FAR_KNOCK_M]
                    counts = bool(big)
                    k = min(big, key=lambda d: d["step"]) if big else k
                if counts and a.outcome != "timeout":
                    a.outcome, kind, step, obj = "knocked", "knock", k["step"], k["object"]
            step = None if step is None else int(min(max(step, a.start), last))
            grip_err = None
            rel = None
            if kind == "close" and step is not None and a.target in idx:
                grip_err = float(np.linalg.norm(self.pos[step][idx[a.target]] - self.eef[step]))
            if kind == "release" and step is not None and a.reference_xy is not None and a.target in idx:
                rel = float(np.linalg.norm(self.pos[step][idx[a.target]][:2] - a.reference_xy))
            n = a.noise
            g = n.get("grasp_offset")
            out.append({
                "attempt": a.index, "skill": a.skill, "conjunct": " ".join(a.conjunct), "target": a.target,
                "reference": a.reference, "start_step": a.start, "end_step": end,
                "phases": [{"label": lab, "step": s} for lab, s in a.phases],
                "grasp_offset_m": None if g is None else [float(g[0]), float(g[1])],
                "approach_height_m": None if g is None else float(g[2]),
                "grasp_timing_steps": n.get("grasp_timing"), "release_timing_steps": n.get("release_timing"),
                "place_offset_m": None if n.get("place_offset") is None else [float(v) for v in n["place_offset"]],
                "action_noise": self.action_noise, "speed_factor": self.speed, "subgoal_achieved": achieved,
                "outcome": a.outcome, "event": kind, "event_step": step, "event_object": obj,
                "grip_error_m": grip_err, "release_dist_m": rel, "knocked": knocks,
                "changes": self._changes(step, end) if step is not None else [], "detail": a.detail,
            })
        return out

    def table(self) -> pa.Table:
        meta = dict(TRUTH_SCHEMA.metadata)
        meta[b"truth"] = json.dumps({"objects": self.objects, "fixtures": list(self.scene.env.fixture_names),
                                     "goal": [list(c) for c in self.scene.env.goal],
                                     "steps": len(self.cmd)}).encode()
        return pa.Table.from_pylist(self.rows(), schema=TRUTH_SCHEMA.with_metadata(meta))
