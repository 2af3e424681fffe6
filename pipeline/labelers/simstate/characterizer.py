"""The `simstate` characterizer: recovery level, failure category and recovery action from
a stage-2 Localization and the episode's simulator evidence (no model).

Inputs: a `Localization` (onset step, phases, events) and the episode's `Evidence`.
Output: `pipeline.records.Characterization` with source "simstate" (raw_text holds the
measurements the decision used, for reviewers).

What the failure did is measured between the onset state and the end of the during-failure
phase (the scene once stable again), per object: how far it moved, its tilt, whether the
robot still holds it.

Level (first rule that matches):
- L4  a non-target object (or a fixture) now obstructs: it moved >= MOVED_M or toppled during
      the failure and ends within OBSTRUCT_M (horizontally) of a target or reference object,
      or ends touching one;
- L3  a target is substantially changed: toppled (tilt >= TOPPLE_DEG), moved >= FAR_M without
      being held at the end (dropped, knocked away), or fell off the table (z < start - 0.1 m);
- L2  limited change, objects still usable: anything moved >= MOVED_M or tilted >= TILT_DEG
      (including a displaced non-target that obstructs nothing);
- L1  nothing changed (e.g. a missed grasp): retrying the action suffices.
Category from the onset event (the event at the onset step; for a VLM onset the nearest
event within 1 s): grasp_missed / grasp_lost -> grasp_failure; object_dropped ->
placement_failure if released within PLACE_NEAR_M of its reference, else grasp_failure;
object_toppled / unintended_displacement / goal_regression -> object_displacement when it is
the target, collision_or_interaction_failure for another object; robot_contact_non_target
-> environmental_obstruction for a fixture, collision_or_interaction_failure for an object;
object_collision -> collision_or_interaction_failure; no event -> other.
Action: a template per (level, category) naming the objects, e.g. "Re-grasp the akita black
bowl and place it on the plate".
"""

from __future__ import annotations

import json

import numpy as np

from pipeline.evidence import Evidence, owner_of
from pipeline.records import Category, Characterization, EventKind, Level, Localization, SimEvent

MOVED_M, FAR_M, OBSTRUCT_M, PLACE_NEAR_M = 0.01, 0.05, 0.15, 0.10
TILT_DEG, TOPPLE_DEG = 10.0, 45.0


def readable(name: str, known: list[str] = ()) -> str:
    """'akita_black_bowl_1' -> 'akita black bowl' ('akita black bowl 1' when `known` holds
    another object of that kind); 'main_table' -> 'table'."""
    def base(n: str) -> str:
        return " ".join(p for p in n.split("_") if not p.isdigit())

    text = base(name)
    if any(k != name and base(k) == text for k in known):
        return name.replace("_", " ")
    return "table" if text == "main table" else text


def _place_phrase(goal: list[list[str]], known: list[str]) -> str:
    phrases = []
    for pred, *args in goal:
        p = pred.lower()
        if p in ("on", "in") and len(args) == 2:
            owner = owner_of(args[1], known)
            region = args[1][len(owner) + 1 :].replace("_region", "").replace("_", " ").strip() if owner != args[1] else ""
            where = f"the {region} of the {readable(owner)}" if region and region != "contain" else f"the {readable(owner)}"
            phrases.append(f"{'place it on' if p == 'on' else 'put it in'} {where}")
        elif p in ("open", "close", "turnon", "turnoff"):
            verb = {"open": "open", "close": "close", "turnon": "turn on", "turnoff": "turn off"}[p]
            phrases.append(f"{verb} the {readable(owner_of(args[0], known))}")
    return " and ".join(dict.fromkeys(phrases)) or "complete the task"


def _onset_event(loc: Localization) -> SimEvent | None:
    at = [e for e in loc.events if e.step == loc.fail_step]
    if at:
        return at[0]
    near = [e for e in loc.events if abs(e.time_s - loc.fail_time_s) <= 1.0]
    return min(near, key=lambda e: abs(e.time_s - loc.fail_time_s)) if near else None


def _changes(ev: Evidence, a: int, b: int) -> dict[str, dict]:
    out = {}
    for o in ev.objects:
        pos = ev.col("position", o)
        out[o] = {"moved": float(np.linalg.norm(pos[b] - pos[a])), "tilt": float(ev.col("tilt_deg", o)[b]),
                  "tilt_gain": float(ev.col("tilt_deg", o)[b] - ev.col("tilt_deg", o)[a]),
                  "fell_off": bool(ev.col("lift", o)[b] < -0.1), "held": ev.grasped[b] == o, "xy": pos[b, :2]}
    return out


def _level(ev: Evidence, ch: dict[str, dict], end: int) -> tuple[Level, str | None]:
    focus = [o for o in ev.targets + ev.references if o in ch]
    for o, c in ch.items():
        if o in ev.targets or o in ev.references:
            continue
        disturbed = c["moved"] >= MOVED_M or c["tilt"] >= TOPPLE_DEG > c["tilt"] - c["tilt_gain"]
        near = [f for f in focus if np.linalg.norm(c["xy"] - ch[f]["xy"]) <= OBSTRUCT_M]
        touching = [f for f in focus if "|".join(sorted((o, f))) in ev.contacts[end]]
        if disturbed and (near or touching):
            return Level.L4, o
    for o in ev.targets:
        c = ch.get(o)
        if c and (c["tilt"] >= TOPPLE_DEG or c["fell_off"] or (c["moved"] >= FAR_M and not c["held"])):
            return Level.L3, None
    if any(c["moved"] >= MOVED_M or c["tilt_gain"] >= TILT_DEG for c in ch.values()):
        return Level.L2, None
    return Level.L1, None


def _category(ev: Evidence, event: SimEvent | None, fixtures: list[str]) -> Category:
    if event is None:
        return Category.other
    k, obj = event.kind, event.object
    if k in (EventKind.grasp_missed, EventKind.grasp_lost):
        return Category.grasp_failure
    if k == EventKind.object_dropped:
        pos = {o: ev.col("position", o)[event.step, :2] for o in ev.objects}
        near = any(np.linalg.norm(pos[obj] - pos[r]) <= PLACE_NEAR_M for r in ev.references if r in pos)
        return Category.placement_failure if near else Category.grasp_failure
    if k in (EventKind.object_toppled, EventKind.unintended_displacement, EventKind.goal_regression):
        return Category.object_displacement if (obj is None or obj in ev.targets) else Category.collision_or_interaction_failure
    if k == EventKind.robot_contact_non_target:
        return Category.environmental_obstruction if obj in fixtures else Category.collision_or_interaction_failure
    if k == EventKind.object_collision:
        return Category.collision_or_interaction_failure
    return Category.other


def _action(level: Level, category: Category, ev: Evidence, obstacle: str | None, toppled: bool) -> str:
    known = ev.objects + ev.fixtures
    place = _place_phrase(ev.goal, known)
    if not ev.targets:  # fixture goals: open / close / turn on / turn off
        text = f"{place[0].upper()}{place[1:]} again"  # an imperative, e.g. "Open the wooden cabinet again"
    else:
        target = " and the ".join(readable(t, known) for t in ev.targets)
        if level is Level.L4 and obstacle:
            text = f"Move the {readable(obstacle, known)} out of the way, then grasp the {target} and {place}"
        elif level is Level.L3 and toppled:
            text = f"Set the {target} upright, then grasp it and {place}"
        elif level is Level.L2 and category is not Category.grasp_failure:
            text = f"Adjust the approach to the {target} and {place}"
        else:
            text = f"Re-grasp the {target} and {place}"
    return text[:200]


def characterize(loc: Localization, ev: Evidence) -> Characterization:
    onset = min(loc.fail_step, len(ev) - 1)
    end = min(max(loc.phases.during[1] - 1, onset), len(ev) - 1)
    ch = _changes(ev, onset, end)
    level, obstacle = _level(ev, ch, end)
    event = _onset_event(loc)
    category = _category(ev, event, ev.fixtures)
    toppled = any(ch[t]["tilt"] >= TOPPLE_DEG for t in ev.targets if t in ch)
    measured = {o: {k: (round(v, 3) if isinstance(v, float) else v) for k, v in c.items() if k != "xy"}
                for o, c in ch.items()}
    raw = json.dumps({"onset_step": onset, "end_step": end, "event": event.kind if event else None,
                      "obstacle": obstacle, "changes": measured})
    return Characterization(key=loc.key, recovery_level=level, failure_category=category,
                            recovery_action=_action(level, category, ev, obstacle, toppled), source="simstate",
                            raw_text=raw)
