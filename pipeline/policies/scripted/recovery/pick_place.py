"""Skill: one attempt at an `on` / `in` conjunct, chosen for the object's current pose.

Attempt k > 0 grasps differently: the k-th best grasp candidate (another yaw or rim side,
for side-lying bottles and mugs as for upright ones), approached from higher up, with the
retry shift of `variation.RetryNoise`. A book that leans or lies tilted is picked up by its
top edge with a tilted hand and turned upright in the hand (stand_book.py); one lying on its
face is pinched by a top corner, turned upright and set down standing (face_book.py); one
standing upside down is first pushed over onto a face (tip_book.py). An object no
grasp reaches clear of its neighbours is first pushed clear, or else grasped where the
hand grazes a fixture least (nudge.py). `take` gets the object into the hand (or says why
it did not), `pick_place_once` places it. The planner calls it again from the live state.
"""

from __future__ import annotations

from collections.abc import Generator
from dataclasses import dataclass
from enum import Enum

import numpy as np

from pipeline.policies.scripted.articulated import wrist_room
from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.hand import Grasp
from pipeline.policies.scripted.motion import Ctx, Plan, free_hand, grasp, place_at
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import (box_centre_offset, destination, inside_region, region_box,
                                                  support_ceiling, turned_foot)
from pipeline.policies.scripted.primitives import Primitive
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.face_book import (crowded_pinches, lying_on_face, pinch_clear_after,
                                                           stand_from_face)
from pipeline.policies.scripted.recovery.long_grasp import lying_long, slide_clear
from pipeline.policies.scripted.recovery.nudge import palm_clear, palm_graze, push, push_plan
from pipeline.policies.scripted.recovery.lying_cup import grasp_by_handle, lying_handle_grasp, place_by_handle
from pipeline.policies.scripted.recovery.near_grasp import pitched_approach, pitched_grasp
from pipeline.policies.scripted.recovery.stand_book import (BookAxes, quarter_turn, slot_size, stand_tilt, stand_up,
                                                            turn_first)
from pipeline.policies.scripted.recovery.tip_book import tip_over, tip_way, upside_down
from pipeline.policies.scripted.skills import place
from pipeline.policies.scripted.slot import place_in_slot, slot_alignment
from pipeline.policies.scripted.stack import carried
from pipeline.policies.scripted.strategies import placement_for

TURN_TOL = 0.15  # radians of yaw still to turn at which the hand may go down to grasp
# a grasp this far (horizontally) from the robot base hovers at least FAR_HOVER_M over it:
# 8 cm over, near full reach, the elbow locked straight and the hand could not turn down
# (measured: libero_spatial's bowl 0.70 m out, 80 steps at the hover, the grasp missed;
# from 14 cm it went down and held at once)
FAR_M = 0.65
FAR_HOVER_M = 0.14


def hover_height(s, g: Grasp, attempt: int) -> float:
    """How high over the grip site the hand stops before going down: higher on retries,
    and over a far rim grasp (only a rim: at zero noise, the second moka pot of libero_10's
    task 8, init state 2, 0.70 m out and hovered over from 14 cm, was set down off the stove
    and then missed; main's 8 cm finished the task)."""
    hover = 0.08 + 0.03 * min(attempt, 2)
    far = g.rim and float(np.linalg.norm(g.pos[:2] - checks.robot_base(s)[:2])) > FAR_M
    return max(hover, FAR_HOVER_M) if far else hover


# a region's plate tilted from level by more than 20 and less than ~78 degrees (a rack's
# slot; a shelf compartment's site is turned on its side, its own strategy places into it)
TILT_COS, TILT_MIN_COS = np.cos(np.radians(20)), 0.2
TILT_MARGIN_M = 0.02  # a lying object's axis comes down this far beyond its radius out from the plate


def tilted_spot(ctx: Ctx, obj: str, target: str) -> np.ndarray | None:
    """Where a lying long object's body goes on a tilted region (the wine rack's top slot),
    or None for a level one. LIBERO's `On` there holds for a body origin up to 10 cm out from
    the plate along its normal (a row of the site's matrix: `SiteObject.under` multiplies by
    it, not its transpose) and within the plate's half size across it (the rack: 2.2 cm);
    the region's level box that `place` keeps to is 1.2 cm deep, and a bottle set down there
    landed on the slot's lip and rolled off it (measured). Out along the normal by its radius
    and a margin, it comes down behind the lip, in the slot. None too where a placement
    strategy takes the object its own way (`place` would ask it)."""
    s = ctx.scene
    region = s.env.region(target)
    normal = region.mat[2]
    if not TILT_MIN_COS < normal[2] < TILT_COS or placement_for(ctx, obj, target) is not None:
        return None
    return region.pos[:2] + normal[:2] * (s.box(obj).size[2] / 2 + TILT_MARGIN_M)


# hand turns tried for a lying long object into a container it overflows as it lies; a
# footprint turned by half a turn more is the same, so each also by -pi and +pi
FIT_TURNS = tuple(np.radians(d) for d in range(-90, 91, 15) if d)
# radians the wrist's last joint keeps inside its limits after the turn, estimated as the
# joint turning by the hand's yaw: the wrist's other joints take part too (a turn estimated
# to leave 0.55 rad drove the joint onto its limit), so the margin is wide
WRIST_ROOM = 0.8


def container_turn(ctx: Ctx, obj: str, target: str) -> float:
    """The hand turn (rad) that fits a lying long object best into a container object's
    region (a basket, a tray), judged by how far its turned footprint overflows the region
    along either axis; 0 where it fits as it lies, or the region is no container's. A
    ketchup bottle lies 15.2 cm long, a basket's region is 12.3 cm square: carried as it
    lay it came down across the rims, its body 2 cm above the region (measured: libero_90
    LIVING_ROOM_SCENE1, timeouts after three tries); along the diagonal it goes in. Of the
    turns that fit as well, the smallest that leaves the wrist's last joint WRIST_ROOM inside
    its limits (else the one leaving it most): a milk carton turned onto that joint's limit
    stalled on the way, and the hand came down short of the basket (measured: libero_object,
    zero noise, init states 0-2)."""
    s = ctx.scene
    r = s.env.region(target)
    if r.joints or r.parent not in s.env.object_names:
        return 0.0
    span = 2 * region_box(s.env, target)[1][:2]

    def overflow(turn: float) -> float:
        size = turned_foot(s, obj, turn)[0] if turn else s.box(obj).size[:2]
        return round(float(np.max(size - span)), 3)  # mm

    over = {t: overflow(t) for t in (0.0, *FIT_TURNS)}
    least = min(over.values())
    if over[0.0] <= max(least, 0.0):
        return 0.0
    fits = [t + k * np.pi for t in FIT_TURNS if over[t] <= least for k in (0, -1, 1)]
    room = {t: wrist_room(s, t) for t in fits}
    roomy = [t for t in fits if room[t] >= WRIST_ROOM]
    return min(roomy, key=abs) if roomy else max(fits, key=room.get)


def book_slot(ctx: Ctx, obj: str, target: str) -> float | None:
    """The slot skill's alignment for a book this attempt stood up in the hand, judged by
    the book's own size (`stand_book.slot_size`); None where a placement strategy before
    the slot skill takes it (a shelf) or it does not fit."""
    if placement_for(ctx, obj, target, before=place_in_slot) is not None:
        return None
    size = slot_size(ctx.scene, obj)
    return None if size is None else slot_alignment(ctx, obj, target, size=size)


def free_hand_for(ctx: Ctx, obj: str) -> Plan:
    """`free_hand`, unless the fingers open on the way to `obj` (`checks.opens_on_the_way`:
    the fist after a drag out, far from what it picks next)."""
    if not checks.opens_on_the_way(ctx.scene, obj):
        yield from free_hand(ctx)


@dataclass(frozen=True)
class Held:
    """How an attempt came to hold its object: by a lying mug's handle (set down as held),
    and the book it stood up in the hand (slotted), if any."""

    by_handle: bool = False
    book: BookAxes | None = None


class Ended(Enum):
    """Why an attempt ended before holding its object."""

    PREPARED = "prepared"  # it stood or turned a book: the next attempt grasps it as it is
    TIPPED = "tipped"  # it only tipped an upside-down book onto a face: not a try
    MISSED = "missed"  # the grasp missed


def take(ctx: Ctx, obj: str, target: str, attempt: int) -> Generator[Primitive, None, Held | Ended]:
    """Get `obj` into the hand, by the way its pose calls for (see the module's doc)."""
    s = ctx.scene
    if carried(s, obj, checks.held(s)):
        return Held()
    face = lying_on_face(s, obj)
    if face is not None and crowded_pinches(s, obj, face) and (shove := push_plan(
            s, obj, None, frees=lambda shift: pinch_clear_after(s, obj, face, shift))) is not None:
        # every corner crowded by a wall: slid clear by the fist first (nudge.py)
        yield from push(ctx, obj, shove)
        face = lying_on_face(s, obj)
    if face is not None and (yield from stand_from_face(ctx, obj, face, attempt)):
        return Ended.PREPARED  # standing (or not)
    if (way := tip_way(s, obj)) is not None:  # upside down: onto a face, stood up from there
        yield from tip_over(ctx, obj, way)
        # not a try when it tipped: the face skill's first pinch (attempt 0) is its best
        # corner; counted, the tipped book got the second, crowded by the caddy's wall,
        # and the pinch missed (measured: a tuning scene, ~100 steps, a timeout)
        return Ended.TIPPED if upside_down(s, obj) is None else Ended.PREPARED
    book = stand_tilt(s, obj)
    turn = None if book is None else turn_first(s, book)
    if turn is not None:
        yield from quarter_turn(ctx, obj, book, *turn)  # nearer standing: the next attempt goes on
        return Ended.PREPARED
    handle = lying_handle_grasp(s, obj) if book is None else None  # a mug on its side: by its handle
    by_handle = handle is not None
    if book is not None:
        yield from stand_up(ctx, obj, book)
    elif by_handle:
        yield from free_hand_for(ctx, obj)
        yield from grasp_by_handle(ctx, obj, handle, hover_m=0.08 + 0.03 * min(attempt, 2))
    else:
        yield from free_hand_for(ctx, obj)
        dest = destination(ctx.scene, obj, target)
        # a candidate whose fingers (and palm) land clear of other objects (they would be
        # clamped too); none: push the object clear of its neighbour first, or else take
        # the one that grazes a fixture least (nudge.py)
        found = palm_clear(s, obj, dest, attempt)
        if found is None and (shove := push_plan(s, obj, dest)) is not None:
            yield from push(ctx, obj, shove)
            dest = destination(ctx.scene, obj, target)
            found = palm_clear(s, obj, dest, attempt)
        if found is None:
            found = palm_graze(s, obj, dest, attempt)
        if found is None:
            choice = checks.clear_grasp_choice(s, obj, dest, attempt)
            found = choice, slide_clear(s, obj, plan_grasp(s, obj, dest, choice))
        pitched = pitched_approach(s, found[1]) if lying_long(s, obj) else None
        if pitched is not None:  # beside the base: fingertips in, wrist out (near_grasp.py)
            by_handle = True  # ... and set down as held, like a mug by its handle: levelled,
            # the hand would tilt the object by the pitch in its fingers
            yield from pitched_grasp(ctx, obj, found[1], pitched)
        else:
            yield from grasp(ctx, obj, dest, choice=found[0], g=found[1],
                             hover_m=hover_height(s, found[1], attempt), turn_tol=TURN_TOL)
    if not carried(s, obj, checks.held(s)):
        ctx.events.append(Note(Outcome.MISSED_GRASP, obj))
        return Ended.MISSED
    return Held(by_handle, book)


def pick_place_once(ctx: Ctx, conjunct: tuple[str, ...], attempt: int) -> Generator[Primitive, None, bool]:
    """One attempt; returns True when it only tipped an upside-down book onto a face (a
    preparation the planner does not count as a try), False otherwise."""
    _, obj, target = conjunct
    s = ctx.scene
    ctx.begin("pick_place", conjunct, obj, target)
    got = yield from take(ctx, obj, target, attempt)
    if isinstance(got, Ended):
        if ctx.truth is not None:
            ctx.truth.end_hand(obj, False)
        return got is Ended.TIPPED
    by_handle, book = got.by_handle, got.book
    if by_handle:
        yield from place_by_handle(ctx, obj, target)
    elif lying_long(s, obj) and s.env.is_region(target) and not s.env.region(target).joints:
        # its body origin is at one end (a bottle's base): centre its length on the region
        # instead, or most of it hangs past one end and it slides off (measured: a bottle
        # laid on the rack by its base fell off behind it); a pan slid onto a shelf keeps its way
        spot = tilted_spot(ctx, obj, target)
        turn = container_turn(ctx, obj, target) if spot is None else 0.0
        if turn:
            centre = region_box(s.env, target)[0][:2]
            xy = inside_region(s.env, target, centre - turned_foot(s, obj, turn)[1])
            yield from place_at(ctx, obj, xy, support_ceiling(s.env, target), turn=turn)
        elif spot is None:
            yield from place(ctx, obj, target, shift=box_centre_offset(s, obj))
        else:
            yield from place_at(ctx, obj, spot - box_centre_offset(s, obj), support_ceiling(s.env, target))
    elif book is not None and (angle := book_slot(ctx, obj, target)) is not None:
        yield from place_in_slot(ctx, obj, target, angle)
    else:
        # measured before letting go onto an object (LIBERO's `On` wants the bodies within 3 cm);
        # not into a region, where a lowered object off its spot is often held off it by a
        # neighbour, and moving it over toppled both (the two moka pots of libero_10 on the stove)
        yield from place(ctx, obj, target, stand=True, recheck=target in s.env.object_names)
    if ctx.truth is not None:
        ctx.truth.end_hand(obj, s.satisfied(conjunct))
    if not s.satisfied(conjunct) and not carried(s, obj, checks.held(s)):
        ctx.events.append(Note(Outcome.MISPLACED, obj))
    return False
