"""Skill: slide a held object by its outer end into a shelf compartment (a region with a
board above it), e.g. a frying pan held by its handle.

Input: a `Ctx` whose hand holds `obj`, and an `in` target region. A compartment of a
shelf has a board a hand's height or less above its floor, so the usual "carry above,
lower, release" would land the object on the board above (or jam the hand into it).
Instead the object is carried level, just above the compartment's floor, to a point in
front of its open side (the one side no wall of the shelf covers), pushed in horizontally
until its far edge is near the back, set down, and let go; the hand holds the object's
outer end (a pan's handle) and stays outside the shelf. `compartment` says whether a
region is such a compartment (None otherwise) and `hand_stays_out` whether the object is
held far enough out for it; a book held at its top edge goes in by `shelf.py` instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted.motion import Ctx, Plan, travel
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import region_box
from pipeline.policies.scripted.primitives import Grip
from pipeline.policies.scripted.stack import carried

HAND_ROOM_M = 0.15  # a board lower than this above the floor leaves no room to lower a hand in
LIFT_M = 0.012  # object's bottom above the floor while sliding
BACK_GAP_M = 0.015  # far edge of the object short of the compartment's back
STAGE_GAP_M = 0.03  # object's near edge this far in front of the opening before sliding
HAND_OUT_M = 0.05  # grip site at least this far outside the open face once the object is in


@dataclass(frozen=True)
class Compartment:
    lo: np.ndarray  # region box (world, axis-aligned)
    hi: np.ndarray
    floor: float  # top of what the object stands on inside
    ceiling: float  # bottom of the board above
    out: np.ndarray  # unit horizontal vector from inside towards the open side


def compartment(scene, region: str) -> Compartment | None:
    env = scene.env
    if not env.is_region(region) or env.region(region).joints:
        return None
    parent = env.region(region).parent
    if parent not in env.fixture_names:
        return None
    pos, half = region_box(env, region)
    lo, hi = pos - half, pos + half
    boxes = env.object_boxes(parent)
    centre = (lo + hi) / 2
    over = [b for b in boxes if np.all(b[0, :2] <= centre[:2]) and np.all(b[1, :2] >= centre[:2])]
    # the floor: the region's bottom or a board of the shelf at it (not `table_height`, which
    # some arenas' table boxes put above the real table top)
    floor = max([float(lo[2])] + [float(b[1, 2]) for b in over if b[1, 2] <= centre[2]])
    if floor > lo[2] + 0.03:
        return None
    ceilings = [float(b[0, 2]) for b in over if b[0, 2] > floor + 0.02]
    if not ceilings or min(ceilings) - floor > HAND_ROOM_M:
        return None
    ceiling = min(ceilings)
    mid_z = (floor + ceiling) / 2
    # the open side: no wall of the shelf (spanning the gap's middle height) just beyond that face
    best = None
    for d in (np.array([1.0, 0.0]), np.array([-1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.0, -1.0])):
        a = int(np.argmax(np.abs(d)))
        face = hi[a] if d[a] > 0 else lo[a]
        walled = False
        for b in boxes:
            if not (b[0, 2] < mid_z < b[1, 2]):
                continue
            near = b[0, a] - 0.04 <= face <= b[1, a] + 0.04  # a box at (or just beyond) this face
            o = 1 - a
            spans = b[0, o] < centre[o] < b[1, o]
            walled |= near and spans
        if not walled:
            # of several open sides, the one facing the robot (-x) or the table's middle wins
            score = float(d @ -centre[:2]) + (0.5 if d[0] < 0 else 0.0)
            if best is None or score > best[0]:
                best = (score, d)
    if best is None:
        return None
    return Compartment(lo=lo, hi=hi, floor=floor, ceiling=ceiling, out=np.array([*best[1], 0.0]))


def _depths(ctx: Ctx, obj: str, comp: Compartment) -> tuple[float, float]:
    """(body's final coordinate along the way out, the open face's coordinate)."""
    s = ctx.scene
    out = comp.out
    a = int(np.argmax(np.abs(out[:2])))
    body = s.env.object_pose(obj)[0]
    box = s.box(obj)
    back_ext = body[a] - box.lo[a] if out[a] > 0 else box.hi[a] - body[a]
    back_face = comp.lo[a] if out[a] > 0 else comp.hi[a]
    open_face = comp.hi[a] if out[a] > 0 else comp.lo[a]
    # the body as deep as the object fits, but inside the region (the goal reads the body)
    depth = back_face + out[a] * (back_ext + BACK_GAP_M)
    inner, outer = back_face + out[a] * 0.01, open_face - out[a] * 0.01
    return float(np.clip(depth, min(inner, outer), max(inner, outer))), float(open_face)


def hand_stays_out(ctx: Ctx, obj: str, comp: Compartment) -> bool:
    """The grip site ends at least HAND_OUT_M outside the open face with the object in."""
    s = ctx.scene
    a = int(np.argmax(np.abs(comp.out[:2])))
    depth, open_face = _depths(ctx, obj, comp)
    grip = depth + (s.eef()[a] - s.env.object_pose(obj)[0][a])
    return bool((grip - open_face) * comp.out[a] >= HAND_OUT_M)


def slide_in(ctx: Ctx, obj: str, comp: Compartment) -> Plan:
    s = ctx.scene
    env = s.env
    yaw = ctx.yaw_hold
    out = comp.out
    a = int(np.argmax(np.abs(out[:2])))
    o = 1 - a

    def body_box():
        body = env.object_pose(obj)[0]
        box = s.box(obj)
        return body, box.lo - body, box.hi - body  # extents relative to the body

    body, rlo, rhi = body_box()
    back_ext = -rlo[a] if out[a] > 0 else rhi[a]  # body to the object's edge facing the back
    depth, open_face = _depths(ctx, obj, comp)
    centre = (comp.lo + comp.hi) / 2
    final = np.zeros(3)
    final[a], final[o] = depth, centre[o]
    stage = final.copy()
    stage[a] = open_face + out[a] * (back_ext + STAGE_GAP_M)

    def hand_for(body_xy: np.ndarray, bottom_z: float) -> np.ndarray:
        """Grip-site target that brings the object's body to `body_xy` and its bottom to `bottom_z`."""
        body, rlo, _ = body_box()
        hold = s.eef() - body
        return np.array([body_xy[0] + hold[0], body_xy[1] + hold[1], bottom_z + hold[2] - rlo[2]])

    carry_z = comp.floor + LIFT_M
    goal = hand_for(stage[:2], carry_z)
    lift_z = s.path_clearance(s.box(obj).centre, stage, 0.05, {obj}) + 0.04 + (s.eef()[2] - s.box(obj).lo[2])
    yield from travel(ctx, goal + [0, 0, 0.05], yaw, 1.0, lift_z)
    yield ctx.move(hand_for(stage[:2], carry_z), gripper=1.0, speed=0.5, yaw=yaw, tol=0.01, max_steps=60,
                   label="stage")
    if not carried(s, obj):
        ctx.events.append(Note(Outcome.DROPPED, obj))
        return
    yield ctx.move(hand_for(final[:2], carry_z), gripper=1.0, speed=0.4, yaw=yaw, tol=0.01, max_steps=90,
                   label="slide_in")
    yield ctx.move(hand_for(final[:2], comp.floor + 0.004), gripper=1.0, speed=0.3, yaw=yaw, tol=0.008,
                   max_steps=30, label="set_down")
    yield Grip(-1.0, ctx.open_steps, label="open")
    eef = s.eef()
    yield ctx.move(eef + [out[0] * 0.04, out[1] * 0.04, 0.0], yaw=yaw, tol=0.015, max_steps=30, label="withdraw")
    yield ctx.move(s.eef() + [0, 0, 0.1], yaw=yaw, tol=0.02, label="retreat")


# ---- the placement strategy (see strategies.py) ---------------------------------------------
def applies(ctx: Ctx, obj: str, target: str) -> Compartment | None:
    """A shelf compartment, the object held by its outer end (a pan's handle): slid in from
    the open side, not lowered onto the board above."""
    comp = compartment(ctx.scene, target)
    return comp if comp is not None and hand_stays_out(ctx, obj, comp) else None


def plan(ctx: Ctx, obj: str, target: str, comp: Compartment) -> Plan:
    return slide_in(ctx, obj, comp)
