"""The scripted generator's own record of what it did: one row per skill attempt.

Inputs: the skills call `begin` / `note` / `end` as they go (at the simulator step the
policy is at), the policy marks each primitive it starts (`mark`) and watches every
executed step (`watch`: gripper command, held object, object poses, all read from
privileged state). Output: `table()`, a `TRUTH_SCHEMA` table written by stage 1 as
`truth.parquet` beside `steps.parquet`.

Per attempt: the skill and its objects, the steps it spanned, the noise actually applied,
and the outcome the expert judges from privileged state (`Outcome`), plus the step and
kind of its decisive event. A pick-and-place failure is judged from the whole trace when
the table is written, since the release an expert makes after giving up comes later.
A hold is a run of >= HELD_ROWS states with the target in hand (touched by both fingers,
or by one while lifted >= LIFT_HELD_M) that lasts into the lift after the close; shorter
runs, or a pinch lost before the lift, are fingers brushing it.
- missed_grasp: no hold in the attempt; event `close`, the first gripper-close command
  after the descent began that lasts >= HELD_ROWS steps (the gripper closing off target).
- lost_grasp: the hold ended while the gripper was still commanded closed; event `slip`,
  the first state without the target in hand.
- dropped: the hold ended after an open command and the target then fell >= DROP_M
  within FALL_ROWS steps (released in the air); event `release`, the open command that
  began the opening it left the hand in.
- misplaced: released and set down (fell < DROP_M), but the conjunct does not hold;
  event `release`, the open command (the release at the wrong place).
- knocked: an object was displaced >= KNOCK_M (or tipped >= TOPPLE_DEG) by contact
  before the attempt's own failure event, or, in an attempt that achieved its subgoal,
  another goal object >= KNOCK_M or any object >= FAR_KNOCK_M; event `knock`, the first
  state it had moved >= MOTION_M (or tilted >= TILT_START_DEG). The attempt's own target
  (only before the fingers began closing on it) and reference count from FAR_KNOCK_M: a
  nudge on the way to a grasp or a placement the expert then makes is not its mistake. An
  object whose goal conjunct holds at the attempt's end is where it should be (a bowl in a
  drawer moves with the drawer): no knock. A goal conjunct that held when the attempt
  began and no longer holds at its end (other than the attempt's own; a drawer bumped
  shut) is knocked too; event `undo`, the first state of the run in which it stopped
  holding, object the conjunct's first argument.
- half_open / not_turned: a drawer/door/knob attempt ended without its conjunct; event
  `let_go`, the step the hand stopped operating the part: the first state after the
  fingers' last touch of it since they closed on it (a handle that slipped out mid-pull),
  or the skill's own let-go (its first let-go phase after the preamble that freed the hand)
  when that came first or the closed fingers never touched it.
- timeout: the episode ended inside the attempt before anything above happened; event
  `timeout`, the attempt's start. (An attempt the episode ended inside whose conjunct holds
  is `achieved`: the runner stops at success before the skill looks.)
Also per attempt, the scene change from the decisive event to the attempt's end, and at
least FALL_ROWS steps after the event (per
object: moved, tilt, tilt gain, fell off, held, position), which `pipeline.truth.derive`
turns into a recovery level. Recording only reads the simulator: actions and the noise
stream are exactly those of an unrecorded run.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
from pydantic import BaseModel

from pipeline.arrow import F32, arrow_schema
from pipeline.policies.scripted.notes import Outcome

KNOCK_M = 0.02  # displacement by contact that counts as knocking an object
FAR_KNOCK_M = 0.05  # ... for an object the goal does not involve, in an achieved attempt
MOTION_M = 0.003  # first motion of a knocked object (its onset)
TOPPLE_DEG, TILT_START_DEG = 45.0, 10.0  # tipped over counts as knocked; its onset: first 10 deg
HELD_ROWS = 3  # states in hand that make a hold (fewer: fingers brushing the object)
LIFT_HELD_M = 0.02  # lifted this much, one finger's touch is a hold
DROP_M, FALL_ROWS = 0.03, 8  # fell >= DROP_M within FALL_ROWS steps of leaving the hand: dropped
OUTCOMES = tuple(Outcome)  # (StrEnum: each equals the string written)
PENDING = "pending"  # a pick-and-place attempt not yet judged (see `rows`)

class PhaseMark(BaseModel):
    label: str
    step: int


class Knock(BaseModel):
    object: str
    moved_m: F32
    step: int


class Change(BaseModel):
    object: str
    moved_m: F32
    tilt_deg: F32
    tilt_gain_deg: F32
    fell_off: bool
    held: bool
    position: list[F32]


class TruthRow(BaseModel):
    """One attempt of `truth.parquet` (the lists are nullable in the file, as first declared)."""

    attempt: int
    skill: str  # pick_place | open | close | turn_on | turn_off
    conjunct: str  # e.g. "on akita_black_bowl_1 plate_1"
    target: str  # object moved, or part operated
    reference: str | None  # where it goes (pick_place)
    start_step: int
    end_step: int  # exclusive
    phases: list[PhaseMark] | None
    grasp_offset_m: list[F32] | None  # xy noise on the grasp point
    approach_height_m: F32 | None  # z noise on the grasp point
    grasp_timing_steps: int | None  # < 0 closes early, > 0 late
    release_timing_steps: int | None
    place_offset_m: list[F32] | None  # xy + release height noise
    action_noise: F32  # per-step action noise scale
    speed_factor: F32
    subgoal_achieved: bool
    outcome: str  # an `Outcome`
    event: str | None  # close | slip | release | knock | undo | let_go | timeout
    event_step: int | None
    event_object: str | None
    grip_error_m: F32 | None  # grip site to the target's body at the close
    release_dist_m: F32 | None  # target to reference, xy, at the release
    knocked: list[Knock] | None
    changes: list[Change] | None  # decisive event -> attempt end
    detail: str


TRUTH_SCHEMA = arrow_schema(TruthRow)


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
    outcome: str = Outcome.TIMEOUT  # (or PENDING)
    event: str | None = None
    event_step: int | None = None
    hand: str | None = None  # the object a pick-and-place attempt judged from the hand trace
    phases: list[tuple[str, int]] = field(default_factory=list)
    noise: dict = field(default_factory=dict)
    detail: str = ""


def _safe(method):
    """Recording must never cost the episode: the first error turns the log off (no truth
    is written for the episode) and the generator goes on exactly as unrecorded."""
    @functools.wraps(method)
    def wrapped(self, *args, **kwargs):
        if self.error is not None:
            return None
        try:
            return method(self, *args, **kwargs)
        except Exception as e:  # noqa: BLE001
            self.error = f"{method.__name__}: {type(e).__name__}: {e}"
            return None
    return wrapped


LET_GO_PHASES = ("let_go", "back_off", "retreat")
FREE_HAND_PHASES = ("release", "back_off")  # a skill's preamble: an empty hand opened and raised


def skill_let_go(phases: list[tuple[str, int]], default: int | None) -> int | None:
    """The step a part skill let go of its part: its first let-go phase after the preamble
    (the preamble's own back-off frees the hand before the part is approached)."""
    k = 0
    while k < len(phases) and phases[k][0] in FREE_HAND_PHASES:
        k += 1
    steps = [s for lab, s in phases[k:] if lab in LET_GO_PHASES]
    return min(steps) if steps else default


class TruthLog:
    """Attempts and a per-step privileged trace of one episode (see the module docstring)."""

    error: str | None = None

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
        self.goal = [tuple(c) for c in env.goal]
        self.sat: list[tuple[bool, ...]] = []  # which goal conjuncts hold in state row t
        self.touch: list[frozenset[str]] = []  # owners other than objects the fingers touch in row t
        self._start()

    @_safe
    def _start(self) -> None:
        self._sample()

    # ---- per step -------------------------------------------------------------------------
    def _sample(self) -> None:
        poses = self.scene.env.object_poses()
        self.pos.append(np.array([poses[o][0] for o in self.objects]).reshape(-1, 3))
        self.quat.append(np.array([poses[o][1] for o in self.objects]).reshape(-1, 4))
        left, right = self.scene.env.finger_contacts()
        self.held.append(self._in_hand(left, right))
        self.touch.append(frozenset((left | right) - set(self.objects)))
        self.eef.append(np.array(self.scene.eef()))
        ok = dict(self.scene.env.goal_conjuncts())
        self.sat.append(tuple(bool(ok.get(c, False)) for c in self.goal))

    def _in_hand(self, left: set[str], right: set[str]) -> str:
        """The object between the fingers: touched by both, or by one while lifted >=
        LIFT_HELD_M above where the episode found it (a pinch on one pad still carries it)."""
        both = [o for o in self.objects if o in left and o in right]
        if both:
            return both[0]
        z0 = self.pos[0][:, 2]
        z = self.pos[-1][:, 2]
        one = [o for i, o in enumerate(self.objects) if (o in left or o in right) and z[i] - z0[i] >= LIFT_HELD_M]
        return one[0] if one else ""

    @_safe
    def watch(self, step: int, action: np.ndarray) -> None:
        """After action `step` was applied: record it and the state it led to (row step + 1)."""
        if step != len(self.cmd):
            return  # not the episode this log began with (e.g. a runner that skipped a step)
        self.cmd.append(float(action[6]))
        self._sample()

    # ---- called by skills and the policy ------------------------------------------------
    @_safe
    def begin(self, skill: str, conjunct: tuple[str, ...], target: str, reference: str | None = None) -> None:
        if self.attempts and self.attempts[-1].end is None:
            self.attempts[-1].end = self.step  # stopped without a verdict: judged in rows()
        ref_xy = None
        if reference is not None:
            ref_xy = self.scene.pos(reference)[:2].copy()
        self.attempts.append(Attempt(len(self.attempts), skill, tuple(conjunct), target, reference, self.step, ref_xy))

    def _open(self) -> Attempt | None:
        return self.attempts[-1] if self.attempts and self.attempts[-1].end is None else None

    @_safe
    def note(self, **noise) -> None:
        if (a := self._open()) is not None:
            a.noise.update(noise)

    @_safe
    def mark(self, label: str) -> None:
        if (a := self._open()) is not None:
            a.phases.append((label, self.step))

    def end(self, outcome: Outcome, detail: str = "") -> None:
        """Close the current attempt with the skill's verdict (articulated parts, knobs)."""
        if outcome not in OUTCOMES:
            raise ValueError(f"outcome {outcome!r} is not one of {OUTCOMES}")
        if (a := self._open()) is None:
            return
        a.end, a.outcome, a.detail = self.step, outcome, detail
        if outcome in (Outcome.HALF_OPEN, Outcome.NOT_TURNED):
            a.event, a.event_step = "let_go", self._let_go(a, skill_let_go(a.phases, a.start))

    @_safe
    def end_hand(self, obj: str, satisfied: bool) -> None:
        """Close a pick-and-place attempt. Success is judged now; a failure is judged from
        the whole trace in `rows()`, since what the hand did with the object (a release the
        expert only makes after giving up) may come after the attempt (module docstring)."""
        if (a := self._open()) is None:
            return
        a.end, a.hand = self.step, obj
        a.outcome = Outcome.ACHIEVED if satisfied else PENDING

    def _judge_hand(self, a: Attempt) -> None:
        obj = a.hand
        run = self._held_run(a, obj)
        if run is None:
            a.outcome, a.event = Outcome.MISSED_GRASP, "close"
            a.event_step = self._first_cmd(a, self._first("descend", a), closing=True)
            return
        s, e = run
        if e is None:  # still in hand when the episode ended: never released
            r = self._first_cmd(a, self._first("lower", a) or s, closing=False)
            a.outcome, a.event, a.event_step = Outcome.MISPLACED, "release", (a.end if r is None else r)
            return
        if self.cmd[e - 1] > 0:
            a.outcome, a.event, a.event_step = Outcome.LOST_GRASP, "slip", e
            return
        r = e - 1  # the open command that began the run of opening it left the hand in
        while r > s and self.cmd[r - 1] <= 0:
            r -= 1
        z = np.array([p[self.objects.index(obj)][2] for p in self.pos[r:e + FALL_ROWS + 1]])
        fell = float(z[0] - z.min()) if len(z) else 0.0
        a.outcome = Outcome.DROPPED if fell >= DROP_M else Outcome.MISPLACED
        a.event, a.event_step = "release", r
        a.detail = f"fell {fell:.3f} m after the release"

    # ---- derived from the trace ---------------------------------------------------------
    def _first(self, label: str, a: Attempt) -> int | None:
        return next((s for lab, s in a.phases if lab == label), None)

    def _held_run(self, a: Attempt, obj: str) -> tuple[int, int | None] | None:
        """The last run of >= HELD_ROWS states with `obj` in hand that starts inside the
        attempt and lasts past the start of its lift: (first row, first row after it, or None
        if it lasts to the end). Shorter runs, or a pinch lost before the lift, are fingers
        brushing the object. The run is followed past the attempt's end."""
        lifted = self._first("pick_lift", a) or a.start
        stop = a.end if a.end is not None else len(self.held)
        best, t, n = None, a.start, len(self.held)
        while t < stop:
            if self.held[t] != obj:
                t += 1
                continue
            e = t
            while e < n and self.held[e] == obj:
                e += 1
            if e - t >= HELD_ROWS and e > lifted:
                best = (t, e if e < n else None)
            t = e
        return best

    def _first_cmd(self, a: Attempt, since: int | None, closing: bool) -> int | None:
        """First step at or after `since` where the gripper command turns to close / open
        and stays so >= HELD_ROWS steps (a one-step flicker barely moves the fingers)."""
        c = np.array(self.cmd) > 0
        for t in range(max(since if since is not None else a.start, a.start), len(c)):
            run = c[t:t + HELD_ROWS]
            turned = (t == 0 or c[t - 1] != closing)
            if turned and len(run) and (run.all() if closing else not run.any()):
                return t
        return None

    def _knocks(self, a: Attempt, end: int) -> list[dict]:
        """Objects that moved >= KNOCK_M in the attempt (the target only before the close;
        the target and reference from FAR_KNOCK_M), and goal conjuncts it undid."""
        out = []
        p0 = self.pos[a.start]
        # the target counts until the fingers start closing on it (or hold it): what the
        # closing fingers do to it is the grasp itself, not a knock
        touched = [t for t in range(a.start, end + 1) if self.held[t] == a.target]
        close = self._first_cmd(a, self._first("descend", a), closing=True) if a.skill == "pick_place" else None
        first_held = min(x for x in (end, close, touched[0] if touched else None) if x is not None)
        in_place = {c[1] for c, ok in zip(self.goal, self.sat[end]) if ok and len(c) == 3}
        own = {a.target, self._owner(a.reference)}
        for i, o in enumerate(self.objects):
            if o in in_place:
                continue
            stop = first_held if o == a.target else end
            rows = range(a.start, stop + 1)
            track = np.array([np.linalg.norm(self.pos[t][i] - p0[i]) for t in rows])
            tilt = np.array([_tilt(self.quat[a.start][i], self.quat[t][i]) for t in rows])
            limit = FAR_KNOCK_M if o in own else KNOCK_M
            if len(track) and (track.max() >= limit or tilt.max() >= TOPPLE_DEG):
                moving = np.flatnonzero((track >= MOTION_M) | (tilt >= TILT_START_DEG))
                out.append({"object": o, "moved_m": float(track.max()), "step": int(moving[0]) + a.start})
        for j, c in enumerate(self.goal):
            if c == tuple(a.conjunct) or not self.sat[a.start][j] or self.sat[end][j]:
                continue
            off = end
            while off > a.start and not self.sat[off - 1][j]:
                off -= 1
            out.append({"object": self._owner(c[1]), "moved_m": 0.0, "step": off, "undo": True})
        return out

    def _owner(self, name: str | None) -> str | None:
        """The object or fixture a region belongs to ('plate_1_contain_region' -> 'plate_1')."""
        if name is None or name in self.objects:
            return name
        known = self.objects + list(self.scene.env.fixture_names)
        hits = [k for k in known if name == k or name.startswith(k + "_")]
        return max(hits, key=len) if hits else name

    def _changes(self, a_row: int, b_row: int) -> list[dict]:
        out = []
        for i, o in enumerate(self.objects):
            t0 = _tilt(self.quat[0][i], self.quat[a_row][i])
            t1 = _tilt(self.quat[0][i], self.quat[b_row][i])
            out.append({"object": o, "moved_m": float(np.linalg.norm(self.pos[b_row][i] - self.pos[a_row][i])),
                        "tilt_deg": t1, "tilt_gain_deg": t1 - t0,
                        "fell_off": bool(self.pos[b_row][i][2] < self.pos[0][i][2] - 0.1),
                        "held": self.held[b_row] == o, "position": self.pos[b_row][i].astype(np.float32).tolist()})
        return out

    def _let_go(self, a: Attempt, skill_step: int) -> int:
        """When the hand stopped operating the part: the first state after the fingers' last
        touch of it since they closed on it (a handle slipping out mid-pull), else the skill's
        own let-go (fingers that closed on air pulled nothing until then)."""
        env = self.scene.env
        name = a.conjunct[1] if len(a.conjunct) > 1 else a.target
        part = env.region(name).parent if env.is_region(name) else name
        grip = min([s for lab, s in a.phases if lab.startswith("grip")], default=a.start)
        touched = [r for r in range(grip, min(skill_step, len(self.touch) - 1) + 1) if part in self.touch[r]]
        return min(skill_step, touched[-1] + 1) if touched else skill_step

    def _unfinished(self, a: Attempt, last: int) -> None:
        """An attempt the episode ended inside (or that stopped without a verdict)."""
        if self.scene.satisfied(a.conjunct):
            a.outcome = Outcome.ACHIEVED  # the goal check ended the episode before the skill looked
        elif a.skill in ("open", "close", "turn_on", "turn_off") and skill_let_go(a.phases, None) is not None:
            a.outcome = Outcome.HALF_OPEN if a.skill in ("open", "close") else Outcome.NOT_TURNED
            a.event, a.event_step = "let_go", self._let_go(a, skill_let_go(a.phases, a.start))
        else:
            a.outcome, a.event, a.event_step = Outcome.TIMEOUT, "timeout", a.start
        if a.end is None:
            a.end = last

    def rows(self) -> list[dict]:
        last = len(self.cmd)  # state rows run 0 .. last
        out = []
        idx = {o: i for i, o in enumerate(self.objects)}
        for a in self.attempts:
            if a.outcome == PENDING:
                self._judge_hand(a)
            if a.end is None or a.outcome == Outcome.TIMEOUT:
                self._unfinished(a, last)
            end = min(a.end, last)
            achieved = a.outcome == Outcome.ACHIEVED
            kind, step, obj = a.event, a.event_step, (a.target if a.event else None)
            knocks = self._knocks(a, end)
            counted = [k for k in knocks if step is None or k["step"] < step]
            if achieved:  # a subgoal reached, but did it disturb the scene?
                counted = [k for k in knocks if k.get("undo") or k["moved_m"] >= FAR_KNOCK_M or
                           (k["object"] in self.goal_objects and k["object"] not in (a.target, a.reference))]
            if counted and a.outcome != Outcome.TIMEOUT:
                k = min(counted, key=lambda d: d["step"])
                a.outcome, kind, step, obj = Outcome.KNOCKED, "undo" if k.get("undo") else "knock", k["step"], k["object"]
            step = None if step is None else int(min(max(step, a.start), last))
            grip_err = rel = None
            if kind == "close" and step is not None and a.target in idx:
                grip_err = float(np.linalg.norm(self.pos[step][idx[a.target]] - self.eef[step]))
            if kind == "release" and step is not None and a.reference_xy is not None and a.target in idx:
                rel = float(np.linalg.norm(self.pos[step][idx[a.target]][:2] - a.reference_xy))
            n = a.noise
            g = n.get("grasp_offset")
            knocks = [{x: v for x, v in k.items() if x != "undo"} for k in knocks]
            out.append({
                "attempt": a.index, "skill": a.skill, "conjunct": " ".join(a.conjunct), "target": a.target,
                "reference": a.reference, "start_step": a.start, "end_step": end,
                "phases": [{"label": lab, "step": s} for lab, s in a.phases],
                "grasp_offset_m": None if g is None else [float(g[0]), float(g[1])],
                "approach_height_m": None if g is None else float(g[2]),
                "grasp_timing_steps": n.get("grasp_timing"), "release_timing_steps": n.get("release_timing"),
                "place_offset_m": None if n.get("place_offset") is None else [float(v) for v in n["place_offset"]],
                "action_noise": self.action_noise, "speed_factor": self.speed, "subgoal_achieved": achieved,
                "outcome": str(a.outcome), "event": kind, "event_step": step, "event_object": obj,
                "grip_error_m": grip_err, "release_dist_m": rel, "knocked": knocks,
                # the scene once the failure played out: an object let go falls for a while,
                # also when the expert let go only after the attempt (see _judge_hand)
                "changes": self._changes(step, min(max(end, step + FALL_ROWS), last)) if step is not None else [],
                "detail": a.detail,
            })
        return out

    def table(self) -> pa.Table:
        """The attempts; when recording failed, no rows and the error in the metadata."""
        rows: list[dict] = []
        if self.error is None:
            try:
                rows = self.rows()
            except Exception as e:  # noqa: BLE001 - a truth we cannot trust is reported, not guessed
                self.error = f"rows: {type(e).__name__}: {e}"
        meta = dict(TRUTH_SCHEMA.metadata)
        meta[b"truth"] = json.dumps({"objects": self.objects, "fixtures": list(self.scene.env.fixture_names),
                                     "goal": [list(c) for c in self.scene.env.goal],
                                     "steps": len(self.cmd), "error": self.error}).encode()
        return pa.Table.from_pylist([] if self.error else rows, schema=TRUTH_SCHEMA.with_metadata(meta))
