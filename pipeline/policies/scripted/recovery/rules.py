"""The recovery expert's decisions as a rule table: precondition -> remedy, in order.

Each round of `planner.recover` builds a `Round` (the next subgoal and what the scene says
about it now) and walks `RULES`: the first rule whose `when` answers (not None) runs its
`then`; a rule with `replan` ends the round (the scene has changed: read it again), one
without lets the next rules look. The last rule always applies: one attempt at the
subgoal. The order is the behaviour: a held stranger is put aside before the arm backs
out, an overhanging drawer is noted before the arm moves, obstructions go before attempts.
Preconditions only read the scene (no noise is drawn, nothing moves).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pipeline.policies.scripted import articulated, drawer_room, insert
from pipeline.policies.scripted.goal import PUT, Predicate
from pipeline.policies.scripted.grasps import leaning, plan_grasp
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.placement import destination
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.back_out import back_out, let_go
from pipeline.policies.scripted.recovery.face_book import lying_on_face, pinch_blockers
from pipeline.policies.scripted.recovery.low_drawer import hook_low_drawer, low_handle
from pipeline.policies.scripted.recovery.lying_cup import lying
from pipeline.policies.scripted.recovery.operate import operate_once
from pipeline.policies.scripted.recovery.pick_place import pick_place_once
from pipeline.policies.scripted.recovery.press_flat import press_flat
from pipeline.policies.scripted.recovery.put_aside import put_aside
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason
from pipeline.policies.scripted.recovery.stand_book import edge_blockers, stand_tilt
from pipeline.policies.scripted.recovery.tip_book import tip_way
from pipeline.policies.scripted.recovery.under_drawer import clear_from_under
from pipeline.policies.scripted.recovery.unwind import unwind
from pipeline.policies.scripted.recovery.variation import RetryNoise
from pipeline.policies.scripted.stack import carried
from pipeline.sim.facts import JointKind

OPEN_FULL = 0.85  # a drawer this far open (of its range) lets a hand reach all of its inside
MAX_TRIES = 4  # attempts per subgoal (each one different)
MAX_ASIDE = 2  # times one obstruction is moved aside
PART_MOVED = 0.01  # metres (or radians) a part may move while the arm backs out, the round still fresh
MAX_UNWIND = 2  # times the arm is unwound to its home joints in one episode
FLAT_M = 0.04  # objects lower than this are grasped with the palm near the table


def debug(*a) -> None:
    if os.environ.get("RECOVERY_DEBUG"):
        print("[recovery]", *a, flush=True)


@dataclass
class Round:
    """One round's subgoal and the facts the rules share (the counters live across rounds)."""

    ctx: Ctx
    goal: list[tuple[str, ...]]
    sub: tuple[str, ...]
    keep: set[str]  # never moved aside: goal objects, targets and their owners
    tries: Counter  # attempts per subgoal
    aside: Counter  # times each object was moved aside
    shut: Counter  # drawers closed because they overhung a goal object
    unwound: Counter  # times the pinned wrist was unwound (key: "wrist")
    pressed: Counter  # times each object leaning in a drawer was pressed flat
    movers: list[str] = field(init=False)  # goal objects still to be moved
    held: str | None = field(init=False)
    stale: bool = field(init=False, default=False)  # a remedy changed what the round read: end it

    def __post_init__(self) -> None:
        s = self.ctx.scene
        self.movers = [c[1] for c in self.goal if c[0] in PUT and not s.satisfied(c) and c[1] in s.env.object_names]
        self.held = checks.held(s)
        if self.held is not None and self.sub[0] in PUT and carried(s, self.sub[1], self.held):
            self.held = self.sub[1]  # the hand holds the stack whose bottom is the subgoal's object

    @property
    def put(self) -> bool:
        return self.sub[0] in PUT


@dataclass(frozen=True)
class Rule:
    name: str
    when: Callable[[Round], Any]  # None: does not apply; else what `then` needs
    then: Callable[[Round, Any], Plan]
    replan: bool = True  # end the round after the remedy


# ---- preconditions and remedies, in table order ---------------------------------------------
def hopeless(r: Round):
    """A goal object fell off the table or is out of reach."""
    return checks.hopeless(r.ctx.scene, r.movers)


def give_up(r: Round, why: tuple[GiveUpReason, str]) -> Plan:
    raise GiveUp(*why)
    yield  # (a generator, like every remedy)


def holds_another(r: Round) -> bool | None:
    return True if r.held is not None and not (r.put and r.sub[1] == r.held) else None


def put_held_aside(r: Round, _: bool) -> Plan:
    r.aside[r.held] += 1
    if r.aside[r.held] > MAX_ASIDE + 1:
        raise GiveUp(GiveUpReason.RETRIES_EXHAUSTED, f"could not put {r.held} aside")
    yield from put_aside(r.ctx, r.held, r.aside[r.held] - 1)


def wrist_pinned(r: Round) -> bool | None:
    return True if checks.wrist_pinned(r.ctx.scene) and r.unwound["wrist"] < MAX_UNWIND else None


def unwind_arm(r: Round, _: bool) -> Plan:
    r.unwound["wrist"] += 1
    debug("unwind the wrist", r.ctx.scene.env.arm_joints()[0].round(2))
    yield from unwind(r.ctx)


def closed_on_nothing(r: Round) -> bool | None:
    """The closed fingers hold nothing, and will not open on the way to the subgoal's
    object (`checks.opens_on_the_way`)."""
    s = r.ctx.scene
    if r.held is not None or s.gripper_open() or checks.opens_on_the_way(s, r.sub[1]):
        return None
    return True


def open_hand(r: Round, _: bool) -> Plan:
    yield from let_go(r.ctx)


def overhanging_drawer(r: Round) -> str | None:
    """An object to go into the very drawer that overhangs it (not one to go elsewhere while
    that drawer is to be closed: libero_90 task 1 reopened the drawer it had to close); read
    before the arm backs out."""
    over = checks.overhanging_drawer(r.ctx.scene, r.sub[1]) if r.sub[0] == Predicate.IN and r.held != r.sub[1] else None
    if over is not None and over != r.sub[2]:
        over = None
    if over is not None and r.shut[over] >= MAX_ASIDE:
        over = None  # (then the grasp is tried as it is)
    return over


def back_out_then_clear_from_under(r: Round, over: str) -> Plan:
    yield from back_out(r.ctx)
    r.shut[over] += 1
    debug("clear from under the drawer", r.sub[1], over)
    yield from clear_from_under(r.ctx, r.sub[1], over, r.shut[over] - 1)


def always(r: Round) -> bool:
    return True


def part_positions(env) -> dict[str, float]:
    """Every drawer's, door's and knob's joint position."""
    return {j: env.joint_position(j) for f in env.fixture_names for j in env.fixture_joints(f)
            if env.joint_frame(j).kind in (JointKind.SLIDE, JointKind.HINGE)}


def arm_back(r: Round, _: bool) -> Plan:
    """Back the arm out when it touches something, sits low or awkwardly (back_out looks).
    A back-out that moved a part (the arm pulled in across a cabinet pushes its open drawer
    half shut) makes the round stale: its subgoal was read with the part where it was
    (measured: the bowl then went into a drawer no longer open, fell off its front, and the
    episode ran out setting it aside from under the drawer)."""
    env = r.ctx.scene.env
    before = part_positions(env)
    yield from back_out(r.ctx)
    after = part_positions(env)
    moved = [j for j in before if abs(after[j] - before[j]) > PART_MOVED]
    if moved:
        debug("the back-out moved", moved, "- replan")
        r.stale = True


def in_the_way(r: Round) -> str | None:
    """What stands in the way of picking and placing the subgoal's object."""
    s, sub, tries = r.ctx.scene, r.sub, r.tries
    if not (r.put and r.held != sub[1] and not insert.can_insert(s, sub)):
        return None
    dest = destination(s, sub[1], sub[2])
    in_way = checks.blockers(s, sub[1], dest, r.keep)
    # whatever stands where the palm goes down: after a failed grasp; at once for a
    # flat object (the palm then comes down low, beside its neighbours) only what
    # stands under the palm's middle: one the palm's edge brushes is nudged aside by
    # the descent (measured: a flat box beside a carton, the plain grasp succeeds;
    # moving the carton first toppled it and cost ~200 steps)
    if tries[sub] > 0 or s.box(sub[1]).size[2] < FLAT_M:
        g = plan_grasp(s, sub[1], dest, tries[sub])
        in_way += checks.grasp_blockers(s, sub[1], g, r.keep, checks.PALM_HALF_M if tries[sub] > 0 else 0.0)
    # whatever an open fingertip would land on: the hand closes on it too
    # (another grasp candidate first, see pick_place_once; aside if none is clear)
    k = checks.clear_grasp_choice(s, sub[1], dest, tries[sub])
    in_way += checks.tip_blockers(s, sub[1], plan_grasp(s, sub[1], dest, k), r.keep)
    # a book on its face is pinched by a top corner instead: what takes a fingertip's spot there
    if (face := lying_on_face(s, sub[1])) is not None:
        in_way += pinch_blockers(s, sub[1], face, r.keep)
    # a tilted book is grasped by its top edge or a corner, the hand tilted: what that hand meets
    # (not one standing upside down that is tipped over instead: no hand closes on it there)
    elif (book := stand_tilt(s, sub[1])) is not None and tip_way(s, sub[1]) is None:
        in_way += edge_blockers(s, sub[1], book, r.keep)
    block = [b for b in in_way if r.aside[b] < MAX_ASIDE]
    if block:
        debug("aside", block)
    return block[0] if block else None


def move_aside(r: Round, obj: str) -> Plan:
    r.aside[obj] += 1
    yield from put_aside(r.ctx, obj, r.aside[obj] - 1)


def under_the_opening_drawer(r: Round) -> tuple[str, np.ndarray] | None:
    """A goal object the drawer about to be opened would overhang: it could not be grasped
    afterwards (only goal objects: moving aside any loose object in the sweep stalled
    libero_90 task 23, a wine bottle beside the white cabinet, and certified no tuning scene)."""
    s, sub = r.ctx.scene, r.sub
    debug("subgoal", sub, "try", r.tries[sub], "held", r.held)
    if not (sub[0] == Predicate.OPEN and (joint := articulated.part_joint(s.env, sub[1])) is not None
            and articulated.is_closed_enough(s.env, sub[1])):  # (an open one only goes a little further)
        return None
    sweep = checks.drawer_sweep(s, joint)
    under = [m for m in r.movers if sweep is not None and checks.under_sweep(s, m, sweep) and r.aside[m] < MAX_ASIDE
             and not checks.sweep_spares(s, m, joint, plan_grasp(s, m))]  # (its first grasp)
    if under:
        debug("aside before opening", under)
    return (under[0], sweep) if under else None


def move_aside_of_sweep(r: Round, how: tuple[str, np.ndarray]) -> Plan:
    obj, sweep = how
    r.aside[obj] += 1
    yield from put_aside(r.ctx, obj, r.aside[obj] - 1, forbid=[sweep])


def drawer_open_above(r: Round) -> str | None:
    """The drawer to open sits under another drawer of the same cabinet that is open (and
    need not be): its front hangs over the lower one's handle, and the hand going for the
    handle meets it (watched: tunetime, KITCHEN_SCENE1's middle drawer left fully open by
    the generator; hooking the bottom one from above pulled on nothing until the horizon)."""
    env, sub = r.ctx.scene.env, r.sub
    if not (sub[0] == Predicate.OPEN and env.is_region(sub[1]) and (joint := articulated.part_joint(env, sub[1]))
            and env.joint_frame(joint).kind == JointKind.SLIDE and articulated.is_closed_enough(env, sub[1])):
        return None
    below = env.region(sub[1])
    needed = {g[1] for g in r.goal if g[0] == Predicate.OPEN} | {articulated.openable(env, g[2]) for g in r.goal
                                                                 if g[0] == Predicate.IN}
    for reg in env.region_names:
        region = env.region(reg)
        other = articulated.part_joint(env, reg) if region.parent == below.parent else None
        if other in (None, joint) or reg in needed or r.shut[reg] >= MAX_ASIDE:
            continue
        fr = env.joint_frame(other)
        if fr.kind == JointKind.SLIDE and region.pos[2] > below.pos[2] and not articulated.is_closed_enough(env, reg):
            debug("close the drawer above first", reg)
            return reg
    return None


def shut_drawer_above(r: Round, region: str) -> Plan:
    r.shut[region] += 1
    yield from operate_once(r.ctx, (Predicate.CLOSE, region))


def proud_in_drawer(r: Round) -> tuple[str, str] | None:
    """An object sticking up out of the drawer jams it: after a failed push, or at once where
    it leans or sits on a wall (a bowl standing on the floor rises over the walls too, but
    the cabinet's opening is taller: it closes)."""
    s, sub = r.ctx.scene, r.sub
    if not (sub[0] == Predicate.CLOSE and (joint := articulated.part_joint(s.env, sub[1])) is not None):
        return None
    proud = [o for o in checks.proud_in_drawer(s, joint) if r.aside[o] < MAX_ASIDE
             and (r.tries[sub] > 0 or leaning(s, o) or checks.perched_in_drawer(s, joint, o))]
    if proud:
        debug("re-place before closing", proud)
    return (proud[0], joint) if proud else None


def re_place(r: Round, how: tuple[str, str]) -> Plan:
    """Pull the drawer fully out, then press a leaning object flat (once), or put it in
    again (flat), or aside."""
    o, joint = how
    s = r.ctx.scene
    again = next((g for g in r.goal if g[0] == Predicate.IN and g[1] == o), None)
    fr = s.env.joint_frame(joint)
    if abs(fr.qpos) < OPEN_FULL * float(np.max(np.abs(fr.range))):
        r.aside[o] += 1
        # the part of it under the cabinet cannot be reached from above: pull it out
        debug("open fully first", joint)
        if low_handle(r.ctx, joint):  # the tilted grip meets the table short of a low bar
            yield from hook_low_drawer(r.ctx, joint)
        else:
            yield from articulated.pull_drawer(r.ctx, joint)
        return
    if not r.pressed[o] and leaning(s, o):
        r.pressed[o] += 1
        debug("press flat", o)
        yield from press_flat(r.ctx, o, joint)
        return
    r.aside[o] += 1
    if again is not None and not leaning(s, o):
        yield from pick_place_once(r.ctx, again, r.aside[o])
    else:
        # a leaning object held by its rim comes down leaning again (a bowl re-placed in the
        # bottom drawer leaned 51 degrees on its front wall, the drawer jammed four times):
        # set down on the table it stands, and the planner puts it in again from there
        yield from put_aside(r.ctx, o, r.aside[o] - 1)


def tried_out(r: Round) -> tuple[GiveUpReason, str] | None:
    if r.tries[r.sub] >= MAX_TRIES:
        return GiveUpReason.RETRIES_EXHAUSTED, f"{' '.join(r.sub)} failed {MAX_TRIES} times"
    return None


def attempt(r: Round, _: bool) -> Plan:
    """One attempt at the subgoal; attempt k of the same subgoal grasps differently."""
    ctx, s, sub, goal = r.ctx, r.ctx.scene, r.sub, r.goal
    if isinstance(ctx.noise, RetryNoise):
        ctx.noise.attempt = r.tries[sub]
    if sub[0] == Predicate.IN and insert.can_insert(s, sub):
        if r.held != sub[1] and lying(s, sub[1]):
            # the insertion grips an upright mug's handle and does nothing with a lying one
            # (a mug on its side for the microwave: five empty tries, `retries_exhausted` at
            # step 1); no skill stands it up, and from above it only lands on the roof
            raise GiveUp(GiveUpReason.NO_PLAN, f"{sub[1]} lies on its side; {sub[2]} takes it upright only")
        yield from insert.insert(ctx, sub, insert.ACROSS_SPEED)  # through a door opening, under a roof
    elif r.put:
        if (yield from pick_place_once(ctx, sub, r.tries[sub])):
            return  # it only tipped a book over (`tip_book`): not a try
    elif sub not in goal and not articulated.is_closed_enough(s.env, sub[1]):  # open, but too short
        going = next(g[1] for g in goal if g[0] == Predicate.IN and articulated.openable(s.env, g[2]) == sub[1])
        yield from drawer_room.make_room(ctx, sub, going)
    else:
        yield from operate_once(ctx, sub)
    if not s.satisfied(sub) or sub not in goal:
        r.tries[sub] += 1


RULES: tuple[Rule, ...] = (
    Rule("goal object off the table or out of reach", hopeless, give_up),
    Rule("the hand holds an object the subgoal does not use", holds_another, put_held_aside),
    Rule("a wrist joint is pinned at its limit", wrist_pinned, unwind_arm, replan=False),
    Rule("the hand closed on nothing", closed_on_nothing, open_hand, replan=False),
    Rule("an open drawer overhangs the object to go into it", overhanging_drawer, back_out_then_clear_from_under),
    Rule("the arm touches something, sits low or awkwardly", always, arm_back, replan=False),
    Rule("something stands in the way of the pick and place", in_the_way, move_aside),
    Rule("the drawer to open would overhang a goal object", under_the_opening_drawer, move_aside_of_sweep),
    Rule("an open drawer above overhangs the drawer to open", drawer_open_above, shut_drawer_above),
    Rule("an object stands proud in the drawer that did not close", proud_in_drawer, re_place),
    Rule("the subgoal failed MAX_TRIES times", tried_out, give_up),
    Rule("one attempt at the subgoal", always, attempt),
)
