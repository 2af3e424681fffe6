"""Skill: slide a held book, laid flat, into a roofed shelf compartment from its open side.

Input: a `Ctx` whose hand holds `obj` (an upright slab held near its top edge, see
`grasps.is_upright_slab`) and a region `target` with a roof over it (a two-layer shelf's
upper level: 13.5 cm between plank and roof, as tall as the book). Output: primitives that
turn the hand so the fingers close along the way in, carry the book in front of the open
side, tilt the hand to point into the shelf (the book then lies flat, its far end ahead of
the fingers), push it in above the plank with the hand outside, release and back out.

The Panda's palm reaches ~10 cm either way along the closing axis, which is vertical once
tilted: the grip site stays PALM_HALF_M above the table. `shelf_opening` says whether this
skill applies (an upright slab, a roofed region that is not a drawer, one open side).
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.grasps import SLAB_THIN_M, is_upright_slab

from pipeline.policies.scripted.hand import closing_yaw
from pipeline.policies.scripted.motion import CARRY_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import region_box
from pipeline.policies.scripted.primitives import Grip
from pipeline.policies.scripted.slot import footprint, has_roof

PALM_HALF_M = 0.115  # grip site above the table when the hand points sideways
PLANK_GAP_M = 0.015  # book's lower face above the shelf floor while pushed in
REACH_IN_M = 0.03  # grip site this far inside the open face at the end (the fingers go in, the palm stays out)
READY_M = 0.13  # grip site this far out before pushing in


def open_side(ctx: Ctx, obj: str, target: str) -> np.ndarray | None:
    """Unit horizontal direction pointing into a roofed region through its one open side,
    for an upright slab; None otherwise."""
    s = ctx.scene
    env = s.env
    if not env.is_region(target) or env.region(target).joints or not is_upright_slab(s, obj):
        return None
    centre, half = region_box(env, target)
    if not has_roof(env, target, obj):
        return None  # open sky: not a shelf
    try:
        walls = env.object_boxes(env.region(target).parent)
    except KeyError:
        return None
    base = env.robot_base()[:2]
    open_sides = []
    for d in (np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, -1.0, 0])):
        face = centre + d * half
        probes = [face + d * t for t in (0.004, 0.008, 0.012, 0.02)]
        if not any(np.all(b[0] <= p) and np.all(p <= b[1]) for b in walls for p in probes):
            open_sides.append(d)
    if len(open_sides) != 1:
        return None
    d = open_sides[0]
    # the way in must not point the hand back at the robot
    if float(-d[:2] @ (centre[:2] - base)) < -0.05:
        return None
    return -d


def shelf_opening(ctx: Ctx, obj: str, target: str) -> np.ndarray | None:
    """The way into the shelf (see `open_side`) when its gap is high enough for this skill."""
    into = open_side(ctx, obj, target)
    if into is None:
        return None
    lo, hi = _height_range(ctx, obj, target)
    return into if lo <= hi else None  # else too low a gap (under a shelf's plank): tip_push.py


def _height_range(ctx: Ctx, obj: str, target: str) -> tuple[float, float]:
    """Lowest and highest grip-site height at which the flat book fits the gap and the
    palm clears the table."""
    s = ctx.scene
    centre, half = region_box(s.env, target)
    floor = s.support_top(centre[:2], 0.005, {obj}, below=centre[2] + half[2])
    thin = SLAB_THIN_M / 2  # half a slab's thickness at most (is_upright_slab)
    lo = max(floor + PLANK_GAP_M + thin, s.table_height() + PALM_HALF_M)
    return lo, centre[2] + half[2] - thin - 0.01


def _clear_lateral(ctx: Ctx, obj: str, target: str, into: np.ndarray, z: float, start: float, end: float) -> float:
    """Sideways position (along `across`) of the grip site for the way in: the book (its
    length across) must stay inside the region; the palm, reaching PALM_HALF_M below the
    grip site and up to ~0.12 m behind it, should pass over no object; nearest the centre."""
    s = ctx.scene
    centre, half = region_box(s.env, target)
    across = np.array([-into[1], into[0]])
    mid = float(centre[:2] @ across)
    room = float(np.abs(half[:2]) @ np.abs(across))
    _, length, _, _ = footprint(s.env.object_corners(obj))
    reach = max(0.0, room - length / 2 - 0.012)
    others = [s.box(o) for o in s.env.object_names if o != obj]
    others = [b for b in others if b.hi[2] > z - PALM_HALF_M]
    best = None
    for lat in np.arange(mid - reach, mid + reach + 1e-6, 0.005):
        hits = 0
        for b in others:
            a = np.array([b.lo[:2] @ into[:2], b.hi[:2] @ into[:2]])
            c = np.array([b.lo[:2] @ across, b.hi[:2] @ across])
            if (min(a) < end - 0.02 and max(a) > start - 0.12) and (min(c) < lat + 0.045 and max(c) > lat - 0.045):
                hits += 1
        cost = 10 * hits + abs(lat - mid)
        if best is None or cost < best[0]:
            best = (cost, float(lat))
    return mid if best is None else best[1]


def slide_into_shelf(ctx: Ctx, obj: str, target: str, into: np.ndarray) -> Plan:
    s = ctx.scene
    env = s.env
    centre, half = region_box(env, target)
    eef = s.eef()
    box = s.box(obj)
    across = np.array([-into[1], into[0], 0.0])
    # yaw whose closing axis runs along `into` (either sign), the one nearer the current yaw
    base_yaw = closing_yaw(into)
    yaw = min((base_yaw, base_yaw - np.pi, base_yaw + np.pi), key=lambda y: abs(y - ctx.yaw_hold))
    lo, hi = _height_range(ctx, obj, target)
    # high in the gap: the wrist, a hand's length behind, then passes over books standing there
    z = max(lo, hi - 0.01)
    open_face = float(centre[:2] @ into[:2]) - float(np.abs(half[:2]) @ np.abs(into[:2]))
    # grip site: along the way in, just outside the open face; sideways where the palm
    # (vertical, behind the fingers) passes over no standing object
    lateral = _clear_lateral(ctx, obj, target, into, z, open_face - READY_M, open_face + REACH_IN_M)
    off = ctx.noise.place_offset()  # the failure generator's seeded error (zero: none)
    ctx.note(place_offset=[float(v) for v in off])
    lateral += float(off[:2] @ across[:2])
    inside = across * lateral + into * (open_face + REACH_IN_M + min(0.0, float(off[:2] @ into[:2])))
    ready = across * lateral + into * (open_face - READY_M)
    inside[2] = ready[2] = z
    # carry upright to above the ready point (hand turned), then tilt there
    hang = eef[2] - box.lo[2]  # the book hangs this far below the grip site while upright
    up = ready.copy()
    up[2] = max(z, s.table_height() + 0.03 + hang)
    lift_z = s.path_clearance(eef, up, 0.5 * float(np.max(box.size[:2])), {obj}) + CARRY_CLEARANCE + hang
    yield from travel(ctx, up, yaw, 1.0, max(lift_z, up[2]))
    ctx.yaw_hold, ctx.approach_hold = yaw, into.copy()
    yield ctx.move(ready + [0, 0, 0.03], gripper=1.0, speed=0.4, yaw=yaw, approach=into, tol=0.012, rot_tol=0.08,
                   max_steps=80, label="tilt")
    if not s.holding(obj):  # (the palm may also touch a neighbour: holding_any could name it)
        ctx.events.append(Note(Outcome.DROPPED, obj))
        ctx.approach_hold = None
        return
    yield ctx.move(ready, gripper=1.0, speed=0.4, yaw=yaw, approach=into, tol=0.008, max_steps=40, label="level")
    yield ctx.move(inside, gripper=1.0, speed=0.3, yaw=yaw, approach=into, tol=0.008, max_steps=80, label="push_in")
    # down to the lowest height the palm allows: the book then drops least onto the shelf
    yield ctx.move(s.eef() + [0, 0, lo - s.eef()[2]], gripper=1.0, speed=0.3, yaw=yaw, approach=into, tol=0.006,
                   max_steps=30, label="lower")
    t = ctx.noise.timing()
    ctx.note(release_timing=t)
    yield Grip(-1.0, ctx.open_steps + 4 + max(t, 0), label="open")
    yield ctx.move(s.eef() - into * 0.08, yaw=yaw, approach=into, tol=0.015, max_steps=30, label="back_out")
    ctx.yaw_hold, ctx.approach_hold = 0.0, None
    yield ctx.move(s.eef() + [0, 0, 0.06], tol=0.02, rot_tol=0.15, max_steps=40, label="untilt")


# the placement strategy (see strategies.py): a book slid upright into a roofed shelf
applies = shelf_opening
plan = slide_into_shelf
