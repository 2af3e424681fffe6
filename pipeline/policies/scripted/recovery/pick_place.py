"""Skill: one attempt at an `on` / `in` conjunct, chosen for the object's current pose.

Attempt k > 0 grasps differently: the k-th best grasp candidate (another yaw or rim side,
for side-lying bottles and mugs as for upright ones), approached from higher up, with the
retry shift of `variation.RetryNoise`. A book that leans or lies tilted is picked up by its
top edge with a tilted hand and turned upright in the hand (stand_book.py). The planner
calls it again from the live state.
"""

from __future__ import annotations

from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.motion import Ctx, Plan, free_hand, grasp
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import box_centre_offset, destination
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.long_grasp import lying_long, slide_clear
from pipeline.policies.scripted.recovery.nudge import palm_clear, push, push_plan
from pipeline.policies.scripted.recovery.lying_cup import grasp_by_handle, lying_handle_grasp, place_by_handle
from pipeline.policies.scripted.recovery.stand_book import quarter_turn, stand_tilt, stand_up, too_steep
from pipeline.policies.scripted.skills import place
from pipeline.policies.scripted.stack import carried

TURN_TOL = 0.15  # radians of yaw still to turn at which the hand may go down to grasp


def pick_place_once(ctx: Ctx, conjunct: tuple[str, ...], attempt: int) -> Plan:
    _, obj, target = conjunct
    s = ctx.scene
    ctx.begin("pick_place", conjunct, obj, target)
    by_handle = False
    if not carried(s, obj, checks.held(s)):
        book = stand_tilt(s, obj)
        if book is not None and too_steep(book):
            yield from quarter_turn(ctx, obj, book)  # nearer standing: the next attempt goes on
            if ctx.truth is not None:
                ctx.truth.end_hand(obj, False)
            return
        handle = lying_handle_grasp(s, obj) if book is None else None  # a mug on its side: by its handle
        by_handle = handle is not None
        if book is not None:
            yield from stand_up(ctx, obj, book)
        elif by_handle:
            yield from free_hand(ctx)
            yield from grasp_by_handle(ctx, obj, handle, hover_m=0.08 + 0.03 * min(attempt, 2))
        else:
            yield from free_hand(ctx)
            dest = destination(ctx.scene, obj, target)
            # a candidate whose fingers (and palm) land clear of other objects (they would be
            # clamped too); none: push the object clear of its neighbour first (nudge.py)
            choice = palm_clear(s, obj, dest, attempt)
            if choice is None and (shove := push_plan(s, obj, dest)) is not None:
                yield from push(ctx, obj, shove)
                dest = destination(ctx.scene, obj, target)
                choice = palm_clear(s, obj, dest, attempt)
            if choice is None:
                choice = checks.clear_grasp_choice(s, obj, dest, attempt)
            yield from grasp(ctx, obj, dest, choice=choice, g=slide_clear(s, obj, plan_grasp(s, obj, dest, choice)),
                             hover_m=0.08 + 0.03 * min(attempt, 2), turn_tol=TURN_TOL)
        if not carried(s, obj, checks.held(s)):
            ctx.events.append(Note(Outcome.MISSED_GRASP, obj))
            if ctx.truth is not None:
                ctx.truth.end_hand(obj, False)
            return
    if by_handle:
        yield from place_by_handle(ctx, obj, target)
    elif lying_long(s, obj) and s.env.is_region(target) and not s.env.region(target).joints:
        # its body origin is at one end (a bottle's base): centre its length on the region
        # instead, or most of it hangs past one end and it slides off (measured: a bottle
        # laid on the rack by its base fell off behind it); a pan slid onto a shelf keeps its way
        yield from place(ctx, obj, target, shift=box_centre_offset(s, obj))
    else:
        yield from place(ctx, obj, target, stand=True)
    if ctx.truth is not None:
        ctx.truth.end_hand(obj, s.satisfied(conjunct))
    if not s.satisfied(conjunct) and not carried(s, obj, checks.held(s)):
        ctx.events.append(Note(Outcome.MISPLACED, obj))
