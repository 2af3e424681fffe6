"""The recovery expert's plan: restore the plan's preconditions, then do the next subgoal;
replan from the live scene after every skill.

Each round reads the scene and decides one thing:
1. a goal object fell off the table or is out of reach -> give up with that reason;
2. the hand holds an object the next subgoal does not use -> put it aside;
3. a wrist joint is pinned at its limit -> unwind the arm to its home joints;
   the arm touches something or sits low / awkward -> back it out (and read the scene
   again when that moved a part: a drawer pushed half shut);
4. the next unmet subgoal (goal order: open, knobs, pick-and-place, close; an implied open
   before putting into a closed drawer) has something in its way -> move that aside; an
   open drawer overhangs the object to move -> push it in, set the object aside, pull it out;
   a goal object the drawer to open would overhang goes aside first (unless the drawer
   passes over it clear, `checks.sweep_spares`);
5. otherwise one attempt at the subgoal; attempt k of the same subgoal grasps differently.
A subgoal that failed MAX_TRIES times, or a budget of steps spent, ends with a reason.
The decisions are a rule table (`rules.RULES`: precondition -> remedy, in order); this
module picks the subgoal and runs the table once per round.
`RECOVERY_DEBUG=1` in the environment prints each decision (for tuning; off by default).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

from pipeline.policies.scripted import articulated, drawer_room
from pipeline.policies.scripted.goal import PUT, Conjunct, Predicate
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.planner import order_goal
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason
from pipeline.policies.scripted.recovery.rules import RULES, Round
from pipeline.policies.scripted.stack import carried


def next_subgoal(ctx: Ctx, steps: list[tuple[str, ...]], goal: list[tuple[str, ...]]) -> tuple[str, ...] | None:
    """The first unmet step; a held goal object's own placement comes first."""
    s = ctx.scene
    todo = []
    for c in steps:
        if c in goal:
            if not s.satisfied(c):
                todo.append(c)
        elif c[0] == Predicate.OPEN:
            # an implied open: only while something must still go in, and the thing is
            # closed or (a drawer) too short for it
            going = [g[1] for g in goal if g[0] == Predicate.IN and not s.satisfied(g) and articulated.openable(s.env, g[2]) == c[1]]
            if going and (articulated.is_closed_enough(s.env, c[1]) or drawer_room.cramped(ctx, c[1], going[0])):
                todo.append(c)
    held = checks.held(s)
    for c in todo:
        if c[0] in PUT and carried(s, c[1], held):
            return c
    return todo[0] if todo else None


def recover(ctx: Ctx, now: Callable[[], int], budget: int | None) -> Plan:
    s = ctx.scene
    goal = [Conjunct.of(c) for c in s.env.goal]
    steps = articulated.close_lower_first(s.env, order_goal(goal, lambda region: articulated.openable(s.env, region)))
    tries: Counter = Counter()
    aside: Counter = Counter()
    shut: Counter = Counter()  # drawers closed because they overhung a goal object
    unwound: Counter = Counter()
    pressed: Counter = Counter()
    keep = {n for c in goal for n in c[1:]}  # never moved aside: goal objects, targets and
    keep |= {s.env.region(n).parent for n in list(keep) if s.env.is_region(n)}  # their owners
    while not s.env.goal_satisfied():
        if budget is not None and now() >= budget:
            raise GiveUp(GiveUpReason.TIMEOUT, f"step budget {budget} spent")
        sub = next_subgoal(ctx, steps, goal)
        if sub is None:
            raise GiveUp(GiveUpReason.NO_PLAN, "every subgoal holds but the goal does not")
        r = Round(ctx, goal, sub, keep, tries, aside, shut, unwound, pressed)
        for rule in RULES:
            how = rule.when(r)
            if how is None:
                continue
            yield from rule.then(r, how)
            if rule.replan or r.stale:
                break
