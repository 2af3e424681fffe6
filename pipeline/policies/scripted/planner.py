"""Goal -> plan: order the goal's conjuncts and run one skill per conjunct.

Input: the BDDL goal (`SimEnv.goal`, lower-case conjunct tuples) and a `Ctx`. Output: a
generator of primitives for the whole episode. Order: open things first, then knobs,
then pick-and-place (a container must be open before something goes in; an object that
another goes onto is placed first), then close.
A drawer that must receive an object is opened first even when the goal does not say
so. The plan starts from whatever state it finds (mid-task starts from saved failure
scenes): satisfied conjuncts are skipped, an object already in hand is placed first,
and a closed gripper holding nothing useful is opened. After one pass it re-checks the
goal and retries unsatisfied conjuncts (an object knocked off by a later step) a few
rounds, then holds still.
"""

from __future__ import annotations

from collections.abc import Callable

from pipeline.policies.scripted import articulated, insert, knobs
from pipeline.policies.scripted.goal import KNOB, PUT, Conjunct, Predicate
from pipeline.policies.scripted.motion import Ctx, Plan, free_hand
from pipeline.policies.scripted.primitives import Move
from pipeline.policies.scripted.skills import pick_place

PREDICATES = tuple(Predicate)
_ORDER = {Predicate.OPEN: 0, Predicate.TURNON: 1, Predicate.TURNOFF: 1, Predicate.ON: 2, Predicate.IN: 2,
          Predicate.CLOSE: 3}
ROUNDS = 2


def skill_for(conjunct: tuple[str, ...]) -> Callable[[Ctx, tuple[str, ...]], Plan]:
    kind = conjunct[0]
    if kind in PUT:
        return pick_place
    if kind == Predicate.OPEN:
        return articulated.open_part
    if kind == Predicate.CLOSE:
        return articulated.close_part
    if kind in KNOB:
        return knobs.turn_knob
    raise ValueError(f"goal predicate {kind!r} of {conjunct} is not one of {PREDICATES}")


def order_goal(
    goal: list[tuple[str, ...]], opener: Callable[[str], str | None]
) -> list[tuple[str, ...]]:
    """Conjuncts in execution order, with an implied `open` before putting into a drawer.

    `opener(region)` names what must be open before something goes into `region`, or None.
    """
    steps = list(goal)
    for c in goal:
        thing = opener(c[2]) if c[0] == Predicate.IN else None
        if thing is not None and Conjunct(Predicate.OPEN, thing) not in steps:
            steps.append(Conjunct(Predicate.OPEN, thing))
    # an object that something else goes onto is put in its own place first (stack the bowls
    # in the tray, not carry a stack there: a stack's bottom bowl is hard to grasp)
    bases = {c[2] for c in steps if c[0] in PUT}
    def rank(ic: tuple[int, tuple[str, ...]]) -> tuple:
        i, c = ic
        return _ORDER[c[0]], c[0] in PUT and c[1] not in bases, i

    ranked = sorted(enumerate(steps), key=rank)
    return [c for _, c in ranked]


def plan_episode(ctx: Ctx) -> Plan:
    s = ctx.scene
    goal = [Conjunct.of(c) for c in s.env.goal]
    for c in goal:
        skill_for(c)  # fail fast on an unknown predicate
    steps = articulated.close_lower_first(s.env, order_goal(goal, lambda region: articulated.openable(s.env, region)))
    held = s.holding_any()
    first = [c for c in steps if c[0] in PUT and c[1] == held and not s.satisfied(c)]
    if first:
        steps = first + [c for c in steps if c not in first]
    else:
        yield from free_hand(ctx)
    for _ in range(ROUNDS):
        for c in steps:
            # an implied open (not in the goal) is only needed while the thing is closed
            if c not in goal and c[0] == Predicate.OPEN and not articulated.is_closed_enough(s.env, c[1]):
                continue
            if c in goal and s.satisfied(c):
                continue
            # into a container under a roof (a microwave): through its door opening
            skill = insert.insert_into if c[0] == Predicate.IN and insert.can_insert(s, c) else skill_for(c)
            yield from skill(ctx, c)
        if s.env.goal_satisfied():
            break
    yield from free_hand(ctx)
    while True:  # done (or given up): hold still with the hand open
        yield Move(target=s.eef(), gripper=-1.0, tol=-1.0, max_steps=10**9, yaw=ctx.yaw_hold, label="idle")
