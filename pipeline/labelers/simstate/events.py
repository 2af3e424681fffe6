"""Failure events seen in an episode's simulator evidence (the simstate rules).

Input: an `Evidence` (pipeline/evidence.py). Output: `SimEvent`s sorted by step. Each rule
reads only the evidence columns, so the same rules run on a freshly computed episode and
on an evidence file read back from disk. Thresholds live in `Thresholds`.

Rules ("closed" = gripper command > 0; "targets" = objects the goal moves, "references" =
what the goal puts them on/in or operates; both from the goal's conjuncts):
- grasp_missed: the gripper closes (and stays closed >= `min_run` steps) with the grip site
  within `near_m` of an object, and within `grasp_window` steps of the close nothing is
  grasped. Step: the close command. Object: the nearest one.
- grasp_lost: a grasp held >= `min_run` steps ends while the gripper is still commanded
  closed, and the object stays ungrasped >= `min_run` steps. Step: the first ungrasped step.
- object_dropped: a grasp ends while the object is supported by nothing but the robot, and
  within `drop_window` steps it falls >= `drop_m` without the goal progressing. Step: the
  open command that released it (if within `grasp_window` steps before), else the release.
- object_toppled: an object not held tilts >= `topple_deg` from its start orientation.
  Step: the last step its tilt was still <= `tilt_start_deg`, plus one.
- unintended_displacement: an object that was never grasped so far moves >= `displace_m`
  from its start. Step: the first step of that motion (displacement >= `motion_m`).
- robot_contact_non_target: the robot touches an object or fixture that is neither a target
  nor a reference for >= `min_run` steps, or moves it >= `motion_m` meanwhile. Step: first
  contact.
- object_collision: a held object touches another object or fixture (not table, not a
  reference) for >= `min_run` steps. Step: first contact.
- goal_regression: goal progress falls below its running maximum and stays below for
  >= `regress_steps`. Step: the first lower step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.evidence import Evidence
from pipeline.records import EventKind, SimEvent


@dataclass(frozen=True)
class Thresholds:
    near_m: float = 0.15
    grasp_window: int = 20  # steps (1 s) for a close to produce a grasp
    min_run: int = 3  # steps a state must last to count (filters one-step flicker)
    drop_window: int = 30
    drop_m: float = 0.03
    topple_deg: float = 45.0
    tilt_start_deg: float = 10.0
    displace_m: float = 0.03
    motion_m: float = 0.005
    regress_steps: int = 5


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open [start, end) runs of True."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(int))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _ev(ev: Evidence, step: int, kind: EventKind, obj: str | None = None, other: str | None = None, detail: str = ""):
    return SimEvent(step=int(step), time_s=float(step / ev.control_hz), kind=kind, object=obj, other=other,
                    detail=detail)


def _pair_mask(ev: Evidence, a: str, b: str) -> np.ndarray:
    key = "|".join(sorted((a, b)))
    return np.array([key in c for c in ev.contacts])


def grasp_missed(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    closed = ev.gripper_command > 0
    held = np.array([g != "" for g in ev.grasped])
    for s, e in _runs(closed):
        if e - s < th.min_run:
            continue
        dist = {o: float(ev.col("eef_distance", o)[s]) for o in ev.objects}
        near = min(dist, key=dist.get)
        if dist[near] > th.near_m or held[s : min(e, s + th.grasp_window)].any():
            continue
        out.append(_ev(ev, s, EventKind.grasp_missed, near, detail=f"closed {dist[near]:.3f} m from {near}, nothing grasped"))
    return out


def grasp_lost_and_dropped(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    closed = ev.gripper_command > 0
    n = len(ev)
    for obj in ev.objects:
        held = np.array([g == obj for g in ev.grasped])
        for s, e in _runs(held):
            if e - s < th.min_run or e >= n:
                continue
            if held[e : e + th.min_run].any():
                continue  # flicker, the grasp resumes
            lift = ev.col("lift", obj)
            window = slice(e, min(n, e + th.drop_window))
            fell = float(lift[e - 1] - lift[window].min())
            supported = any(c.startswith(f"{obj}|") or c.endswith(f"|{obj}") for c in ev.contacts[e - 1]
                            if "robot" not in c.split("|"))
            progressed = ev.goal_progress[window].max() > ev.goal_progress[e - 1]
            if fell >= th.drop_m and not supported and not progressed:
                opens = [t for t in range(max(s, e - th.grasp_window), e) if not closed[t] and (t == 0 or closed[t - 1])]
                out.append(_ev(ev, opens[-1] if opens else e, EventKind.object_dropped, obj,
                               detail=f"released unsupported, fell {fell:.3f} m"))
            elif closed[e - 1] and closed[e]:
                out.append(_ev(ev, e, EventKind.grasp_lost, obj, detail="slipped out of the closed gripper"))
    return out


def toppled(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    for obj in ev.objects:
        tilt = ev.col("tilt_deg", obj)
        over = np.flatnonzero((tilt >= th.topple_deg) & np.array([g != obj for g in ev.grasped]))
        if len(over):
            k = int(over[0])
            calm = np.flatnonzero(tilt[:k] <= th.tilt_start_deg)
            step = int(calm[-1]) + 1 if len(calm) else 0
            out.append(_ev(ev, step, EventKind.object_toppled, obj, detail=f"tilted {tilt[k]:.0f} deg"))
    return out


def displaced(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    for obj in ev.objects:
        held = np.flatnonzero([g == obj for g in ev.grasped])
        first_held = int(held[0]) if len(held) else len(ev)
        disp = ev.col("displacement", obj)[:first_held]
        far = np.flatnonzero(disp >= th.displace_m)
        if len(far):
            k = int(far[0])
            still = np.flatnonzero(disp[:k] < th.motion_m)
            step = int(still[-1]) + 1 if len(still) else 0
            out.append(_ev(ev, step, EventKind.unintended_displacement, obj, detail=f"moved {disp[k]:.3f} m without a grasp"))
    return out


def robot_contacts(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    relevant = set(ev.targets) | set(ev.references)
    for thing in ev.objects + ev.fixtures:
        if thing in relevant:
            continue
        disp = ev.col("displacement", thing) if thing in ev.objects else np.zeros(len(ev))
        for s, e in _runs(_pair_mask(ev, thing, "robot")):
            moved = float(disp[s:e].max() - disp[s])
            if e - s >= th.min_run or moved >= th.motion_m:
                out.append(_ev(ev, s, EventKind.robot_contact_non_target, thing, "robot",
                               detail=f"{(e - s) / ev.control_hz:.2f} s of contact, moved it {moved:.3f} m"))
                break
    return out


def held_collisions(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    out = []
    for thing in ev.objects + ev.fixtures:
        if thing in ev.references:
            continue
        for obj in set(g for g in ev.grasped if g and g != thing):
            mask = _pair_mask(ev, obj, thing) & np.array([g == obj for g in ev.grasped])
            runs = [r for r in _runs(mask) if r[1] - r[0] >= th.min_run]
            if runs:
                out.append(_ev(ev, runs[0][0], EventKind.object_collision, obj, thing, detail=f"held {obj} hit {thing}"))
    return out


def goal_regression(ev: Evidence, th: Thresholds) -> list[SimEvent]:
    best = np.maximum.accumulate(ev.goal_progress)
    for s, e in _runs(ev.goal_progress < best - 1e-6):
        if e - s >= th.regress_steps:
            return [_ev(ev, s, EventKind.goal_regression, detail=f"goal progress {best[s]:.2f} -> {ev.goal_progress[s]:.2f}")]
    return []


RULES = (grasp_missed, grasp_lost_and_dropped, toppled, displaced, robot_contacts, held_collisions, goal_regression)


def detect_events(ev: Evidence, th: Thresholds | None = None) -> list[SimEvent]:
    th = th or Thresholds()
    events = [e for rule in RULES for e in rule(ev, th)]
    return sorted(events, key=lambda e: (e.step, e.kind))
