"""Skills: goal conjuncts turned into primitive sequences, reading live state as they go.

`pick_place` grasps an object and `place`s it; `place` asks the placement strategies
(`PLACEMENTS`, an ordered registry: the first whose `applies` answers takes the object in
its own way) and otherwise puts the object down at `placement.place_choice`'s spot. A
skill returns when its conjunct holds or it gives up; it never reads the goal flag to
act, only to stop early or retry (a real expert looks at what it did).

Layer: above the strategies (`strategies.py`) and motion (`motion.py`); below the
planners (`planner.py`, `recovery/`).
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.motion import Ctx, Plan, free_hand, grasp, place_at
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import destination, inside_region, place_choice, support_ceiling
from pipeline.policies.scripted.stack import carried
from pipeline.policies.scripted.strategies import placement_for


def place(ctx: Ctx, obj: str, target: str, stand: bool = False, shift: np.ndarray | None = None,
          recheck: bool = False) -> Plan:
    """`stand`, `recheck`: see `place_at` (the recovery expert). `shift`: xy subtracted from the spot of a
    plain placement (the recovery expert centres a lying long object's length on the region;
    the own-way placements above, shelves, slots, a pan slid in, are not shifted)."""
    found = placement_for(ctx, obj, target)
    if found is not None:
        strategy, how = found
        yield from strategy.plan(ctx, obj, target, how)
        return
    xy, _, turn = place_choice(ctx.scene, obj, target)
    if shift is not None:
        # centring the length may not take the body origin off the region: a frying pan's
        # origin is in its pan, 9 cm from its box centre, and was set down beside the stove's
        # cook region, on the stove but not `On` it, four times running
        xy = inside_region(ctx.scene.env, target, xy - shift)
    yield from place_at(ctx, obj, xy, support_ceiling(ctx.scene.env, target), stand=stand, turn=turn,
                        recheck=recheck)


def pick_place(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    _, obj, target = conjunct
    s = ctx.scene
    for _ in range(ctx.max_attempts):
        if s.satisfied(conjunct):
            return
        ctx.begin("pick_place", conjunct, obj, target)
        if not carried(s, obj):
            yield from free_hand(ctx)
            yield from grasp(ctx, obj, destination(ctx.scene, obj, target))
            if not carried(s, obj):
                ctx.events.append(Note(Outcome.MISSED_GRASP, obj))
                if ctx.truth is not None:  # held for a while, then gone: a lost grasp, not a miss
                    ctx.truth.end_hand(obj, False)
                continue
        yield from place(ctx, obj, target)
        if ctx.truth is not None:  # a no-op when place already ended the attempt
            ctx.truth.end_hand(obj, s.satisfied(conjunct))
        if not s.satisfied(conjunct) and not carried(s, obj):
            ctx.events.append(Note(Outcome.MISPLACED, obj))
