"""Skill: put an object down where it blocks nothing (a wrongly held object, or an
obstruction on the approach or placement path), then let go and rise."""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.motion import Ctx, Plan, free_hand, grasp, place_at
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason

# the palm reaches ~10 cm either way along its closing axis: carrying an object aside, the
# whole hand keeps above what it passes (measured: a pudding carried aside past a part-open
# drawer at the object's own width swept the drawer shut, and opening it again cost ~170 steps)
HAND_REACH_M = 0.1


def goal_points(ctx: Ctx, moved: str | None = None) -> list[np.ndarray]:
    """Where the goal's objects and targets are: a set-aside object must keep clear of them
    (not of where it stands itself, `moved`: a goal object put aside before its drawer opens)."""
    s = ctx.scene
    pts = []
    for c in s.env.goal:
        for name in c[1:]:
            if name == moved:
                continue
            try:
                pts.append(s.pos(name))
            except KeyError:
                continue
    return pts


def put_aside(ctx: Ctx, obj: str, attempt: int = 0, forbid: list[np.ndarray] = ()) -> Plan:
    """`forbid`: (2, 3) boxes the spot must keep clear of (e.g. a drawer's sweep)."""
    s = ctx.scene
    if checks.held(s) != obj:
        yield from free_hand(ctx)
        # (at the usual height, not near its top: a milk carton held by its gable stayed wedged
        # between the open fingers and came up again with the hand: libero_10 task 1 init 1)
        yield from grasp(ctx, obj, None, choice=checks.clear_grasp_choice(s, obj, None, attempt),
                         hover_m=0.08 + 0.03 * min(attempt, 2))
        if checks.held(s) != obj:
            return
    spot = checks.free_spot(s, obj, goal_points(ctx, obj), forbid, corridor_m=HAND_REACH_M)
    if spot is None:
        raise GiveUp(GiveUpReason.NO_PLAN, f"no free spot on the table to put {obj} aside")
    yield from place_at(ctx, obj, spot, corridor_m=HAND_REACH_M)
