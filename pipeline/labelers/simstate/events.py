"""Failure events seen in an episode's simulator evidence (the simstate rules).

Input: an `Evidence` (pipeline/evidence.py). Output: `SimEvent`s sorted by step. Each rule
reads only the evidence columns, so the same rules run on a freshly computed episode and
on an evidence file read back from disk. Thresholds live in `Thresholds`; they were tuned
against the scripted generator's truth (`recover bench-localize`) on runs that are not the
one reported in the README (seed 1 init states 2-3, seed 2 init state 4).

Terms: "closed" = gripper command > 0; a "close" is a run of closed steps, runs apart by
fewer than `merge_gap` open steps merged (the command flickering while the hand still
descends is one close), starting at its first run of >= `min_run` closed steps (twitches
alone are no close, nor fewer than `close_steps` closed steps in all: fingers pre-shaped for
a handle); a "hold" is a run of >= `hold_steps` states with the object
grasped, runs apart by fewer than `min_run` states merged (shorter runs are fingers
brushing or pinching it); "targets" = objects the goal
moves, "references" = what the goal puts them on/in or operates, "operated" = fixtures an
open/close/turn-on/turn-off conjunct names (all from the goal's conjuncts).

Rules:
- grasp_missed: a close (>= `min_run` steps) with the grip site within `near_m` of an
  object (the nearest target if one is that near, else the nearest object), during which no
  hold begins and the robot does not touch an operated fixture for >= `operate_steps`
  (gripping a knob or pushing a drawer with a fist is not a grasp; a close that held an
  object, or only brushed the fixture, was a grasp). A hold that never raised its object
  >= `lift_m` and ended with the gripper still closed (squeezed on its support, it slipped
  out) is no grasp either, nor one that tipped it >= `pinch_tilt_deg` while its origin rose
  < `pinch_lift_m` (an edge pinched: the origin rose with the tilt).
  A close farther than `near_m` from every object is a grasp missed on the nearest target
  too when that target is within `reach_m`, the close lasted >= `air_close_steps` and the
  fingers ended shut on nothing (opening < `shut_m`): the hand shut on air short of the
  target (a close that came early, one blocked by the rack or the cabinet above it, or on a
  bottle's neck or a pan's handle far from the body's origin). Fingers around a drawer
  handle stay ~1.7 cm apart, and a close of a few steps is the command flickering: neither
  is a grasp.
  Step: the first closed step. Object: that object.
- grasp_lost: a hold ends while the gripper is still commanded closed, after it had raised
  the object >= `lift_m`. Step: the first ungrasped step. (For this rule, the drop and the
  misplacement below, a hold that the same object's next hold follows within
  `regrip_steps` did not end: the object shifted in the fingers, or the command flickered
  open and shut again, and it never left the hand.)
- object_dropped: a hold ends while the object is supported by nothing but the robot, and
  within `drop_window` steps it falls >= `drop_m`, and goal progress does not rise (for >=
  `min_run` states above its level when the hold began or ended, whichever is lower: a
  predicate flickering true once is no progress) within 2 * `drop_window` steps, nor
  before the next hold begins (a release into a basket that lands there is a placement).
  Step: the open command that released it (if within `grasp_window` steps before), else
  the release.
- object_misplaced: a hold of a target that raised it >= `lift_m` ends after an open command
  (within `grasp_window` steps before the hold ends) and is no drop (it was set down on
  something, or fell less than `drop_m`), and goal progress does not rise (as for a drop)
  within 2 * `drop_window` steps nor before the next hold begins: the target was let go
  where the goal does not want it. Step: that open command (the release at the wrong place).
- object_toppled: an object not held, and not held in the last `drop_window` steps (a
  release or a slip that tips it is that event, an object tipping over inside its
  container is no failure), tilts >= `topple_deg` from its start orientation, and was not
  held since it began tipping. A target that goes over while a close near it is under way
  is that grasp attempt's failure (grasp_missed / grasp_lost), not a topple. Step: the last
  step its tilt was still <= `tilt_start_deg`, plus one.
- unintended_displacement: an object moves >= `displace_m` from its start (a target or a
  reference >= `own_displace_m`: a nudge on the way to a grasp that then holds, or a
  basket nudged by what is put into it, is no failure) before it is first held; a target's
  motion only counts before the first close near it (the closing fingers moving it are the
  grasp). Step: the first step of that motion (displacement >= `motion_m`); when the robot
  was touching it then (contacts apart by fewer than `merge_gap` steps joined), the first
  step of that touch on which it had moved >= `motion_m` (a push jiggles the object in
  place before it slides).
- robot_contact_non_target: the robot touches an object that is neither a target nor a
  reference and moves it >= `displace_m` meanwhile (a touch that moves nothing is no
  failure), or a fixture that is neither for >= `fixture_contact_steps`. Step: first
  contact.
- object_collision: a held object touches another object that is not a reference and that
  moves >= `displace_m` meanwhile, or a fixture that is not a reference for >=
  `fixture_contact_steps`; what the object rested on when the hold began is not a
  collision. Step: first contact.
- part_not_operated: a session of working an operated fixture, after which goal progress
  has not risen by the start of the next session (or the episode's end): a drawer left
  half open, a knob not turned. A session is the robot touching the fixture with the
  gripper closed on nothing (a handle, a knob, a fist pushing) for >= `operate_steps`, runs
  apart by fewer than `merge_gap` steps merged; or a close that touches it for fewer steps
  than that, holds nothing, is farther than `near_m` from every object for >=
  `operate_steps` and then opens (the fingers closed on air where the knob is). Step: the
  first step after the session (the let-go).
- goal_regression: goal progress falls below its running maximum and stays below for
  >= `regress_steps`. Step: the first lower step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.evidence import Evidence, owner_of
from pipeline.records import EventKind, SimEvent


@dataclass(frozen=True)
class Thresholds:
    near_m: float = 0.17  # grip site to an object's body origin for a close to be a grasp on it
    reach_m: float = 0.30  # ... or to the nearest target, for a long close that shut on air
    air_close_steps: int = 20  # 1 s: a close on air that long was meant as a grasp (shorter: command flicker)
    shut_m: float = 0.005  # finger opening of a hand shut on nothing (~1 mm; ~17 mm around a drawer handle)
    grasp_window: int = 20  # steps (1 s): an open command this soon before a drop released it
    min_run: int = 3  # steps a state must last to count (filters one-step flicker)
    # a close has this many closed steps in all: 3 closed steps, then a neutral command,
    # pre-shape the fingers for a drawer handle (7.9 -> 5.1 cm apart; the command ramps 0.25
    # a step), no grasp (tunewide: called a missed grasp 5.4 s before the truth)
    close_steps: int = 5
    merge_gap: int = 8  # closed runs apart by fewer open steps are one close (command flicker)
    hold_steps: int = 6  # states in hand that make a hold (fewer: brushing, a pinch that slips)
    regrip_steps: int = 20  # a hold of the same object again this soon: it never left the hand
    lift_m: float = 0.003  # a hold that never raised its object this much (its first motion, as motion_m)
    # and slipped out of the closed fingers was no grasp; nor one that tipped it this far while
    # its origin rose less than this (fingers closed early on a box's edge: 29 deg, 2.0 cm up,
    # then out; the truth's missed grasp 1.2 s before the slip. Slips after a real grasp on the
    # tuning runs: at most 11 deg below 2.5 cm)
    pinch_tilt_deg: float = 20.0
    pinch_lift_m: float = 0.025
    drop_window: int = 30
    drop_m: float = 0.03
    topple_deg: float = 45.0
    tilt_start_deg: float = 10.0
    displace_m: float = 0.02  # the truth's knock: an object pushed 2 cm
    own_displace_m: float = 0.05  # a target (before its grasp) or a reference must move this far
    motion_m: float = 0.003
    fixture_contact_steps: int = 40  # 2 s pressed against a fixture the goal does not involve
    operate_steps: int = 10  # contact with an operated fixture that is an attempt to operate it
    regress_steps: int = 5


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open [start, end) runs of True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(int))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _merged(mask: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """Runs of True, runs apart by fewer than `gap` False steps joined."""
    out: list[list[int]] = []
    for s, e in _runs(mask):
        if out and s - out[-1][1] < gap:
            out[-1][1] = e
        else:
            out.append([s, e])
    return [(int(s), int(e)) for s, e in out]


def _ev(ev: Evidence, step: int, kind: str, obj: str | None = None, other: str | None = None, detail: str = ""):
    return SimEvent(step=int(step), time_s=float(step / ev.control_hz), kind=kind, object=obj, other=other,
                    detail=detail)


def operated(ev: Evidence) -> list[str]:
    """Fixtures (or objects) an open / close / turn-on / turn-off conjunct operates."""
    known = ev.objects + ev.fixtures
    return list(dict.fromkeys(owner_of(a, known) for p, *args in ev.goal
                              if p.lower() in ("open", "close", "turnon", "turnoff") for a in args))


def holds(ev: Evidence, th: Thresholds, obj: str | None = None) -> list[tuple[int, int, str]]:
    """(start, end, object) of every hold (of `obj`, or of any object); runs in hand apart by
    fewer than `min_run` states are one hold (contact flickers while the fingers settle)."""
    out = []
    for o in ([obj] if obj else ev.objects):
        out += [(s, e, o) for s, e in _merged(np.array([g == o for g in ev.grasped]), th.min_run)
                if e - s >= th.hold_steps]
    return sorted(out)


def unlifted_slip(ev: Evidence, th: Thresholds, s: int, e: int, obj: str) -> bool:
    """A hold that never raised its object `lift_m` and ended with the gripper still closed:
    the fingers squeezed it on its support and it slipped out, a grasp that never took. So
    is one that tipped it `pinch_tilt_deg` or more while raising its origin less than
    `pinch_lift_m`: the fingers pinched an edge, and the origin rose with the tilt."""
    closed = ev.gripper_command > 0
    if e >= len(ev) or not (closed[e - 1] and closed[e]):
        return False
    lift, tilt = ev.col("lift", obj), ev.col("tilt_deg", obj)
    rise = float(lift[s:e].max() - lift[s])
    tipped = float(tilt[s:e].max() - tilt[s])
    return rise < th.lift_m or (rise < th.pinch_lift_m and tipped >= th.pinch_tilt_deg)


def closes(ev: Evidence, th: Thresholds) -> list[tuple[int, int]]:
    """Closes, each from its first closed run of >= `min_run` steps: one-step twitches of the
    command before it (a hand that closes early in steps while its descent is blocked) are
    part of the close but not its start, and twitches alone close no gripper; nor do fewer
    than `close_steps` closed steps in all (fingers pre-shaped for a handle)."""
    closed = ev.gripper_command > 0
    out = []
    for s, e in _merged(closed, th.merge_gap):
        held = [a for a, b in _runs(closed[s:e]) if b - a >= th.min_run]
        if held and int(closed[s:e].sum()) >= th.close_steps:
            out.append((s + int(held[0]), e))
    return out


def _shut_on_air(ev: Evidence, th: Thresholds, s: int, e: int, dist: dict[str, float]) -> str | None:
    """The target a close farther than `near_m` from every object was a grasp on, if any."""
    targets = [o for o in ev.targets if o in dist and dist[o] <= th.reach_m]
    if not targets or e - s < th.air_close_steps or e >= len(ev):  # (cut by the horizon: still under way)
        return None
    return min(targets, key=dist.get) if ev.gripper_opening[e - 1] < th.shut_m else None


def grasp_missed(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    all_holds = holds(ev, th)
    starts = [s for s, e, o in all_holds if not unlifted_slip(ev, th, s, e, o)]
    parts = operated(ev)
    touching_part = np.zeros(len(ev), bool)
    for p in parts:
        touching_part |= ev.pair_mask(p, "robot")
    for s, e in closes(ev, th):
        dist = {o: float(ev.col("eef_distance", o)[s]) for o in ev.objects}
        near_targets = [o for o in ev.targets if o in dist and dist[o] <= th.near_m]
        near = min(near_targets or dist, key=dist.get) if dist else None
        if near is not None and dist[near] > th.near_m:
            near = _shut_on_air(ev, th, s, e, dist)
        squeezed = any(s <= h < e for h, _, _ in all_holds)  # it held an object: a grasp, not a fist on a part
        # working the part (a handle or knob gripped, a fist pushing) touches it a while; a
        # grasp that brushed it on the way does not
        worked = int(touching_part[s:e].sum()) >= th.operate_steps
        if near is None or any(s <= h < e for h in starts) or (worked and not squeezed):
            continue
        out.append(_ev(ev, s, "grasp_missed", near, detail=f"closed {dist[near]:.3f} m from {near}'s origin, "
                                                            "nothing held"))
    return out


def grasp_lost_and_dropped(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    closed = ev.gripper_command > 0
    n = len(ev)
    all_holds = holds(ev, th)
    for s, e, obj in all_holds:
        if e >= n or unlifted_slip(ev, th, s, e, obj):
            continue  # still held at the end, or a grasp that never took (grasp_missed)
        if any(h[2] == obj and e < h[0] < e + th.regrip_steps for h in all_holds):
            continue  # held again at once: it shifted in the fingers, it never left the hand
        lift = ev.col("lift", obj)
        window = slice(e, min(n, e + th.drop_window))
        fell = float(lift[e - 1] - lift[window].min())
        supported = bool(ev.touching_what(e - 1, obj) - {"robot"})
        nxt = next((h for h, _, _ in all_holds if h > e), n)
        base = min(ev.goal_progress[s], ev.goal_progress[e - 1])  # a predicate true in the hand is no placement yet
        after = ev.goal_progress[e:max(e + 1, min(nxt, e + 2 * th.drop_window))] > base + 1e-6
        progressed = any(b - a >= th.min_run or b == len(after) for a, b in _runs(after))  # not a 1-state flicker
        opens = [t for t in range(max(s, e - th.grasp_window), e) if not closed[t] and (t == 0 or closed[t - 1])]
        if fell >= th.drop_m and not supported and not progressed:
            out.append(_ev(ev, opens[-1] if opens else e, "object_dropped", obj,
                           detail=f"released unsupported, fell {fell:.3f} m"))
        elif closed[e - 1] and closed[e]:
            out.append(_ev(ev, e, "grasp_lost", obj, detail="slipped out of the closed gripper"))
        elif opens and obj in ev.targets and not progressed and float(lift[s:e].max() - lift[s]) >= th.lift_m:
            # (a set-down needs a pick-up: fingers touching a target they never raised, then
            # opening, placed nothing)
            out.append(_ev(ev, opens[-1], EventKind.object_misplaced, obj,
                           detail=f"released and set down (fell {fell:.3f} m), goal progress unchanged"))
    return out


def toppled(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    grasping = {o: np.zeros(len(ev), bool) for o in ev.targets}  # a close near the target under way
    for s, e in closes(ev, th):
        for o in grasping:
            if o in ev.objects and ev.col("eef_distance", o)[s] <= th.near_m:
                grasping[o][s:e] = True
    for obj in ev.objects:
        tilt = ev.col("tilt_deg", obj)
        held = np.array([g == obj for g in ev.grasped])
        recently = np.convolve(held.astype(int), np.ones(th.drop_window + 1, int))[: len(held)] > 0
        over = np.flatnonzero((tilt >= th.topple_deg) & ~recently)
        if len(over):
            k = int(over[0])
            calm = np.flatnonzero(tilt[:k] <= th.tilt_start_deg)
            step = int(calm[-1]) + 1 if len(calm) else 0
            if held[step:k].any():
                continue  # it began tipping in the hand: the release or slip is the event
            if obj in grasping and grasping[obj][k]:
                continue  # it went over while the fingers closed on it: that grasp is the event
            out.append(_ev(ev, step, "object_toppled", obj, detail=f"tilted {tilt[k]:.0f} deg"))
    return out


def displaced(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    first_close = {}
    for s, _ in closes(ev, th):
        for o in ev.targets:
            if o in ev.objects and o not in first_close and ev.col("eef_distance", o)[s] <= th.near_m:
                first_close[o] = s
    for obj in ev.objects:
        held = np.flatnonzero([g == obj for g in ev.grasped])
        stop = min(int(held[0]) if len(held) else len(ev), first_close.get(obj, len(ev)))
        disp = ev.col("displacement", obj)[:stop]
        limit = th.own_displace_m if obj in ev.references or obj in ev.targets else th.displace_m
        far = np.flatnonzero(disp >= limit)
        if len(far):
            k = int(far[0])
            still = np.flatnonzero(disp[:k] < th.motion_m)
            step = int(still[-1]) + 1 if len(still) else 0
            touch = [r for r in _merged(ev.pair_mask(obj, "robot"), th.merge_gap) if r[0] <= k <= r[1]]
            if touch:  # pushed: it jiggles in place under the hand before it slides
                step = min(step, touch[0][0] + int(np.argmax(disp[touch[0][0]:k + 1] >= th.motion_m)))
            out.append(_ev(ev, step, EventKind.unintended_displacement, obj, detail=f"moved {disp[k]:.3f} m without a grasp"))
    return out


def _moved_during(ev: Evidence, thing: str, s: int, e: int) -> float:
    if thing not in ev.objects:
        return 0.0
    pos = ev.col("position", thing)
    return float(np.linalg.norm(pos[s:min(len(ev), e + 1)] - pos[s], axis=1).max())


def robot_contacts(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    relevant = set(ev.targets) | set(ev.references)
    for thing in ev.objects + ev.fixtures:
        if thing in relevant:
            continue
        for s, e in _runs(ev.pair_mask(thing, "robot")):
            moved = _moved_during(ev, thing, s, e)
            if moved >= th.displace_m or (thing not in ev.objects and e - s >= th.fixture_contact_steps):
                out.append(_ev(ev, s, "robot_contact_non_target", thing, "robot",
                               detail=f"{(e - s) / ev.control_hz:.2f} s of contact, moved it {moved:.3f} m"))
                break
    return out


def held_collisions(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    for hs, he, obj in holds(ev, th):
        for thing in ev.objects + ev.fixtures:
            if thing in ev.references or thing == obj or ev.touching(hs, obj, thing):
                continue  # a reference, or what it rested on when the hold began
            mask = ev.pair_mask(obj, thing)[hs:he]
            for s, e in _runs(mask):
                s, e = s + hs, e + hs
                moved = _moved_during(ev, thing, s, e)
                if moved >= th.displace_m or (thing not in ev.objects and e - s >= th.fixture_contact_steps):
                    out.append(_ev(ev, s, "object_collision", obj, thing,
                                   detail=f"held {obj} hit {thing} (moved it {moved:.3f} m)"))
                    break
    return out


def parts_not_operated(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    free = np.array([g == "" for g in ev.grasped])
    dist = np.stack([ev.col("eef_distance", o) for o in ev.objects]) if ev.objects else np.full((1, len(ev)), np.inf)
    far = dist.min(axis=0) > th.near_m
    for part in operated(ev):
        touching = ev.pair_mask(part, "robot")
        gripping = touching & (ev.gripper_command > 0) & free  # a handle, a knob, or a fist pushing
        sessions = [r for r in _merged(gripping, th.merge_gap) if r[1] - r[0] >= th.operate_steps]
        for s, e in closes(ev, th):  # closed on air where the part is (a knob missed), then let go
            brushed = touching[s:e].sum() < th.operate_steps
            if e < len(ev) and brushed and (free[s:e] & far[s:e]).sum() >= th.operate_steps:
                sessions.append((s, e))
        sessions.sort()
        for i, (s, e) in enumerate(sessions):
            until = sessions[i + 1][0] if i + 1 < len(sessions) else len(ev)
            before = ev.goal_progress[s - 1] if s > 0 else ev.goal_progress[0]
            if ev.goal_progress[s:max(until, s + 1)].max() <= before + 1e-6:
                out.append(_ev(ev, e, "part_not_operated", part, "robot",
                               detail=f"{(e - s) / ev.control_hz:.2f} s working {part}, goal progress unchanged"))
                break
    return out


def goal_regression(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    best = np.maximum.accumulate(ev.goal_progress)
    for s, e in _runs(ev.goal_progress < best - 1e-6):
        if e - s >= th.regress_steps:
            return [_ev(ev, s, EventKind.goal_regression, detail=f"goal progress {best[s]:.2f} -> {ev.goal_progress[s]:.2f}")]
    return []


RULES = (grasp_missed, grasp_lost_and_dropped, toppled, displaced, robot_contacts, held_collisions,
         parts_not_operated, goal_regression)


def detect_events(ev: Evidence, th: Thresholds | None = None) -> list[SimEvent]:
    th = th or Thresholds()
    events = [e for rule in RULES for e in rule(ev, th)]
    return sorted(events, key=lambda e: (e.step, e.kind))
