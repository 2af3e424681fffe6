"""The recovery expert's plan: restore the plan's preconditions, then do the next subgoal;
replan from the live scene after every skill.

Each round reads the scene and decides one thing:
1. a goal object fell off the table or is out of reach -> give up with that reason;
2. the hand holds an object the next subgoal does not use -> put it aside;
3. the arm touches something or sits low / awkward -> back it out;
4. the next unmet subgoal (goal order: open, knobs, pick-and-place, close; an implied open
   before putting into a closed drawer) has something in its way -> move that aside; an
   open drawer overhangs the object to move -> push it in, set the object aside, pull it out;
5. otherwise one attempt at the subgoal; attempt k of the same subgoal grasps differently.
A subgoal that failed MAX_TRIES times, or a budget of steps spent, ends with a reason.
`RECOVERY_DEBUG=1` in the environment prints each decision (for tuning; off by default).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable

import numpy as np

from pipeline.policies.scripted import articulated, drawer_room, insert
from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.planner import order_goal
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.back_out import back_out, let_go
from pipeline.policies.scripted.recovery.operate import operate_once
from pipeline.policies.scripted.recovery.pick_place import pick_place_once
from pipeline.policies.scripted.recovery.put_aside import put_aside
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason
from pipeline.policies.scripted.recovery.under_drawer import clear_from_under
from pipeline.policies.scripted.recovery.variation import RetryNoise
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.placement import destination
from pipeline.policies.scripted.stack import carried

OPEN_FULL = 0.85  # a drawer this far open (of its range) lets a hand reach all of its inside
MAX_TRIES = 4  # attempts per subgoal (each one different)
MAX_ASIDE = 2  # times one obstruction is moved aside
FLAT_M = 0.04  # objects lower than this are grasped with the palm near the table


def _debug(*a) -> None:
    if os.environ.get("RECOVERY_DEBUG"):
        print("[recovery]", *a, flush=True)


def next_subgoal(ctx: Ctx, steps: list[tuple[str, ...]], goal: list[tuple[str, ...]]) -> tuple[str, ...] | None:
    """The first unmet step; a held goal object's own placement comes first."""
    s = ctx.scene
    todo = []
    for c in steps:
        if c in goal:
            if not s.satisfied(c):
                todo.append(c)
        elif c[0] == "open":
            # an implied open: only while something must still go in, and the thing is
            # closed or (a drawer) too short for it
            going = [g[1] for g in goal if g[0] == "in" and not s.satisfied(g) and articulated.openable(s.env, g[2]) == c[1]]
            if going and (articulated.is_closed_enough(s.env, c[1]) or drawer_room.cramped(ctx, c[1], going[0])):
                todo.append(c)
    held = checks.held(s)
    for c in todo:
        if c[0] in ("on", "in") and carried(s, c[1], held):
            return c
    return todo[0] if todo else None


def recover(ctx: Ctx, now: Callable[[], int], budget: int | None) -> Plan:
    s = ctx.scene
    goal = [tuple(c) for c in s.env.goal]
    steps = articulated.close_lower_first(s.env, order_goal(goal, lambda region: articulated.openable(s.env, region)))
    tries: Counter = Counter()
    aside: Counter = Counter()
    shut: Counter = Counter()  # drawers closed because they overhung a goal object
    keep = {n for c in goal for n in c[1:]}  # never moved aside: goal objects, targets and
    keep |= {s.env.region(n).parent for n in list(keep) if s.env.is_region(n)}  # their owners
    while not s.env.goal_satisfied():
        if budget is not None and now() >= budget:
            raise GiveUp(GiveUpReason.TIMEOUT, f"step budget {budget} spent")
        sub = next_subgoal(ctx, steps, goal)
        if sub is None:
            raise GiveUp(GiveUpReason.NO_PLAN, "every subgoal holds but the goal does not")
        movers = [c[1] for c in goal if c[0] in ("on", "in") and not s.satisfied(c) and c[1] in s.env.object_names]
        hopeless = checks.hopeless(s, movers)
        if hopeless is not None:
            raise GiveUp(*hopeless)
        held = checks.held(s)
        if held is not None and sub[0] in ("on", "in") and carried(s, sub[1], held):
            held = sub[1]  # the hand holds the stack whose bottom is the subgoal's object
        if held is not None and not (sub[0] in ("on", "in") and sub[1] == held):
            aside[held] += 1
            if aside[held] > MAX_ASIDE + 1:
                raise GiveUp(GiveUpReason.RETRIES_EXHAUSTED, f"could not put {held} aside")
            yield from put_aside(ctx, held, aside[held] - 1)
            continue
        if held is None and not s.gripper_open():
            yield from let_go(ctx)
        # an object to go into the very drawer that overhangs it (not one to go elsewhere
        # while that drawer is to be closed: libero_90 task 1 reopened the drawer it had to close)
        over = checks.overhanging_drawer(s, sub[1]) if sub[0] == "in" and held != sub[1] else None
        if over is not None and over != sub[2]:
            over = None
        if over is not None and shut[over] >= MAX_ASIDE:
            over = None  # (then the grasp is tried as it is)
        yield from back_out(ctx)
        if over is not None:
            shut[over] += 1
            _debug("clear from under the drawer", sub[1], over)
            yield from clear_from_under(ctx, sub[1], over, shut[over] - 1)
            continue
        if sub[0] in ("on", "in") and held != sub[1] and not insert.can_insert(s, sub):
            dest = destination(ctx.scene, sub[1], sub[2])
            in_way = checks.blockers(s, sub[1], dest, keep)
            # whatever stands where the palm goes down: after a failed grasp; at once for a
            # flat object (the palm then comes down low, beside its neighbours) only what
            # stands under the palm's middle: one the palm's edge brushes is nudged aside by
            # the descent (measured: a flat box beside a carton, the plain grasp succeeds;
            # moving the carton first toppled it and cost ~200 steps)
            if tries[sub] > 0 or s.box(sub[1]).size[2] < FLAT_M:
                g = plan_grasp(s, sub[1], dest, tries[sub])
                in_way += checks.grasp_blockers(s, sub[1], g, keep, checks.PALM_HALF_M if tries[sub] > 0 else 0.0)
            # whatever an open fingertip would land on: the hand closes on it too
            # (another grasp candidate first, see pick_place_once; aside if none is clear)
            k = checks.clear_grasp_choice(s, sub[1], dest, tries[sub])
            in_way += checks.tip_blockers(s, sub[1], plan_grasp(s, sub[1], dest, k), keep)
            block = [b for b in in_way if aside[b] < MAX_ASIDE]
            if block:
                _debug("aside", block)
                aside[block[0]] += 1
                yield from put_aside(ctx, block[0], aside[block[0]] - 1)
                continue
        _debug("subgoal", sub, "try", tries[sub], "held", held)
        if (sub[0] == "open" and (joint := articulated.part_joint(s.env, sub[1])) is not None
                and articulated.is_closed_enough(s.env, sub[1])):  # (an open one only goes a little further)
            # an object the opened drawer would overhang cannot be grasped afterwards: first aside
            sweep = checks.drawer_sweep(s, joint)
            # (only goal objects: moving aside any loose object in the sweep stalled libero_90
            # task 23, a wine bottle beside the white cabinet, and certified no tuning scene)
            under = [m for m in movers if sweep is not None and checks.under_sweep(s, m, sweep) and aside[m] < MAX_ASIDE]
            if under:
                _debug("aside before opening", under)
                aside[under[0]] += 1
                yield from put_aside(ctx, under[0], aside[under[0]] - 1, forbid=[sweep])
                continue
        if sub[0] == "close" and tries[sub] > 0 and (joint := articulated.part_joint(s.env, sub[1])) is not None:
            # after a failed push: an object sticking up out of the drawer jams it; pull the
            # drawer fully out, then put it in again (flat), or aside
            proud = [o for o in checks.proud_in_drawer(s, joint) if aside[o] < MAX_ASIDE]
            if proud:
                _debug("re-place before closing", proud)
                o = proud[0]
                aside[o] += 1
                again = next((g for g in goal if g[0] == "in" and g[1] == o), None)
                fr = s.env.joint_frame(joint)
                if abs(fr.qpos) < OPEN_FULL * float(np.max(np.abs(fr.range))):
                    # the part of it under the cabinet cannot be reached from above: pull it out
                    _debug("open fully first", joint)
                    yield from articulated.pull_drawer(ctx, joint)
                    continue
                if again is not None:
                    yield from pick_place_once(ctx, again, aside[o])
                else:
                    yield from put_aside(ctx, o, aside[o] - 1)
                continue
        if tries[sub] >= MAX_TRIES:
            raise GiveUp(GiveUpReason.RETRIES_EXHAUSTED, f"{' '.join(sub)} failed {MAX_TRIES} times")
        if isinstance(ctx.noise, RetryNoise):
            ctx.noise.attempt = tries[sub]
        if sub[0] == "in" and insert.can_insert(s, sub):
            yield from insert.insert(ctx, sub)  # through a door opening, under a roof
        elif sub[0] in ("on", "in"):
            yield from pick_place_once(ctx, sub, tries[sub])
        elif sub not in goal and not articulated.is_closed_enough(s.env, sub[1]):  # open, but too short
            going = next(g[1] for g in goal if g[0] == "in" and articulated.openable(s.env, g[2]) == sub[1])
            yield from drawer_room.make_room(ctx, sub, going)
        else:
            yield from operate_once(ctx, sub)
        if not s.satisfied(sub) or sub not in goal:
            tries[sub] += 1
