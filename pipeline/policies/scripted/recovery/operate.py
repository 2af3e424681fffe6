"""Skill: one attempt at an articulated conjunct (open / close a drawer or door, turn a
knob), re-opening or re-closing whatever a failure changed. Uses the plain expert's
part skills with a single attempt; a retry differs by `RetryNoise`'s shift."""

from __future__ import annotations

from pipeline.policies.scripted import articulated, drawer_room, knobs
from pipeline.policies.scripted.goal import Predicate
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.recovery.low_drawer import hook_low_drawer, low_handle


def operate_once(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    kind = conjunct[0]
    saved, ctx.max_attempts = ctx.max_attempts, 1
    try:
        if kind == Predicate.OPEN and drawer_room.part_way_out(ctx.scene.env, conjunct[1]):
            yield from drawer_room.finish_opening(ctx, conjunct)  # not the tilted pull again
        elif kind == Predicate.OPEN and (joint := articulated.part_joint(ctx.scene.env, conjunct[1])) \
                and low_handle(ctx, joint):
            if not articulated.is_closed_enough(ctx.scene.env, conjunct[1]):
                return
            yield from hook_low_drawer(ctx, joint)
        elif kind == Predicate.OPEN:
            yield from articulated.open_part(ctx, conjunct)
        elif kind == Predicate.CLOSE:
            yield from articulated.close_part(ctx, conjunct)
        else:
            yield from knobs.turn_knob(ctx, conjunct)
    finally:
        ctx.max_attempts = saved
