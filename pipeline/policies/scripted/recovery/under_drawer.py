"""Skill: get a goal object out from under an open drawer that overhangs it (a bowl left
under the front of the top drawer it was to go into).

No grasp reaches it there: the forearm comes down onto the drawer (measured, libero_goal
"open the top drawer and put the bowl inside": the hand stopped 15 cm over the bowl on
every rim side). Closing the drawer, putting the object aside and opening the drawer by its
handle again works but costs ~450 steps. So: push the drawer in only as far as uncovers
the object (and a hand's margin), put the object aside near by, out of the drawer's sweep,
and open the drawer again. Each stage checks the live state; the planner replans after the
skill.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.articulated import FINGER_HALF, handle_box, open_sign, part_joint, pull_drawer
from pipeline.policies.scripted.drawer_room import drag_out
from pipeline.policies.scripted.goal import Conjunct, Predicate
from pipeline.policies.scripted.grasps import plan_grasp
from pipeline.policies.scripted.hand import Grasp
from pipeline.policies.scripted.motion import Ctx, Plan, grasp, place_at, travel
from pipeline.policies.scripted.notes import Outcome
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.put_aside import goal_points
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason

HAND_PAD_M = 0.01  # pushed this far past the object's edge
# a drawer out at least this far is dragged out again by a fist behind its front wall: the
# handle pull costs more (tilt, reach, pull, untilt; measured: libero_goal's drawer pushed
# back to 4.3 cm out, the fist 17 and 43 steps faster in the two tuning scenes that left it
# so, both certified under 520 steps since); shorter, by its handle, with twice the plain
# expert's reach and 1.6 times its pull speed (the reach 14 steps instead of 24, the pull
# 16 instead of 24)
FIST_ROOM_M = 0.04
REACH_SPEED, PULL_SPEED = 0.8, 0.8
# the spot beyond the drawer's sweep may lie this far across it, either way (the nearest
# side is often taken: libero_goal's bowl had a cream cheese and the stove toward the robot)
ACROSS_M = 0.18
AWAY_MAX_M = 0.8  # ... and at most this far from the robot base (lowering far out is slow)


def pull_side(env, joint: str) -> tuple[int, float]:
    """The world axis (0: x, 1: y) the drawer of `joint` opens along, and its sign."""
    fr = env.joint_frame(joint)
    pull = fr.axis * open_sign(fr.range)
    k = int(np.argmax(np.abs(pull[:2])))
    return k, float(np.sign(pull[k]))


def palm_overhang(s, obj: str, joint: str, g: Grasp) -> float:
    """How far (m) the palm of grip `g` reaches past `obj`'s edge toward the drawer of
    `joint`, less what a drawer may meet of it (`checks.PALM_MEETS_M`)."""
    k, d = pull_side(s.env, joint)
    palm, box = checks.palm_footprint(g), s.box(obj)
    past = float(box.lo[k] - palm[0, k]) if d > 0 else float(palm[1, k] - box.hi[k])
    return max(0.0, past - checks.PALM_MEETS_M)


def uncover_distance(ctx: Ctx, obj: str, joint: str, overhang: float) -> float:
    """How far (m) the drawer must go in so that its parts no longer overhang `obj` (+pad),
    nor the palm's way down to it, which reaches `overhang` past it (`palm_overhang`)."""
    s = ctx.scene
    k, d = pull_side(s.env, joint)
    boxes = s.env.joint_part_boxes(joint)
    front = float(boxes[:, 1, k].max()) if d > 0 else float(-boxes[:, 0, k].min())
    edge = float(s.box(obj).lo[k]) if d > 0 else float(-s.box(obj).hi[k])
    return max(0.0, front - edge + overhang + HAND_PAD_M)


def away_from_drawer(s, obj: str, joint: str, attempt: int, candidates: int = checks.GRASP_TRIES) -> int:
    """Which grasp candidate (`plan_grasp`'s choice) to take: of the first few, the one whose
    grip site lies farthest from the drawer's front (the wrist and forearm come down over
    it, and a drawer just pushed in still sticks out close by); `attempt` takes the next."""
    k, d = pull_side(s.env, joint)
    boxes = s.env.joint_part_boxes(joint)
    front = float(boxes[:, 1, k].max()) if d > 0 else float(boxes[:, 0, k].min())
    ranked = sorted(range(candidates), key=lambda c: -d * (plan_grasp(s, obj, None, c).pos[k] - front))
    return ranked[attempt % candidates]


def beyond_sweep(s, obj: str, joint: str, sweep: np.ndarray, overhang: float = 0.0) -> np.ndarray | None:
    """A spot for the object's body just beyond the fully opened drawer (moved out along the
    drawer's pull, 6 to 10 cm clear of it and `palm_overhang` more: a pudding set down 6 cm
    out had the palm's way down under the drawer again once it was open, measured; and
    across it up to ACROSS_M either way): the short way out of its sweep, close to where it
    goes in next. Of the spots clear of everything, the nearest the robot base (lowering an
    object far out is slow: measured, 60 steps 0.81 m out), none beyond AWAY_MAX_M from it.
    None when none is clear (then `free_spot`, whose spots lie farther from the drawer:
    measured, libero_goal's bowl 0.33 m off to the side cost ~50 steps of carrying there
    and back)."""
    k, d = pull_side(s.env, joint)
    box = s.box(obj)
    body = s.env.object_pose(obj)[0][:2]
    base = checks.robot_base(s)[:2]
    table = s.table_height()
    others = [b for _, b in s.obstacle_boxes({obj}) if b[1, 2] > table + 0.005]
    best = None
    for gap in (0.06, 0.08, 0.1):  # (`checks.under_sweep` wants it 5 cm clear)
        for across in np.arange(-ACROSS_M, ACROSS_M + 1e-9, 0.03):
            shift = np.zeros(2)
            out = gap + overhang
            shift[k] = (sweep[1, k] + out - box.lo[k]) if d > 0 else (sweep[0, k] - out - box.hi[k])
            shift[1 - k] = across
            lo, hi = box.lo[:2] + shift - 0.01, box.hi[:2] + shift + 0.01
            if any(np.all(b[0, :2] <= hi) and np.all(lo <= b[1, :2]) for b in others):
                continue
            r = float(np.linalg.norm(body + shift - base))
            if r <= AWAY_MAX_M and (best is None or r < best[0]):
                best = (r, body + shift)
    return None if best is None else best[1]


def push_in(ctx: Ctx, joint: str, dist: float) -> Plan:
    """A fist at the drawer's front pushes it in by `dist` (the fist closes on the way)."""
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    pull = fr.axis * open_sign(fr.range)
    box, k, d = handle_box(env, joint, pull)
    front = box[1, k] if d > 0 else box[0, k]
    pos = (box[0] + box[1]) / 2
    pos[k] = front + d * 0.035
    yaw = np.pi / 2 if k == 1 else 0.0  # the palm's long side across the push
    ctx.yaw_hold = yaw
    hover = pos + [0, 0, 0.08]
    yield from travel(ctx, hover, yaw, 1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
    yield ctx.move(pos, gripper=1.0, speed=0.6, yaw=yaw, tol=0.01, max_steps=40, label="face_drawer")
    target = pos.copy()
    target[k] = front + d * FINGER_HALF - d * dist
    yield ctx.move(target, gripper=1.0, speed=0.6, yaw=yaw, tol=0.008, max_steps=40, label="push_in")
    # back off and up, opening the hand on the way; the aside grasp's approach opens it the
    # rest of the way (it commands the hand open for ~30 steps before the descent)
    yield ctx.move(s.eef() + pull / np.linalg.norm(pull) * 0.03 + [0, 0, 0.08], gripper=-1.0, yaw=yaw, tol=0.02,
                   max_steps=20, label="retreat")


def clear_from_under(ctx: Ctx, obj: str, region: str, attempt: int = 0) -> Plan:
    s, env = ctx.scene, ctx.scene.env
    joint = part_joint(env, region)
    fr = env.joint_frame(joint)
    sign = open_sign(fr.range)
    out = sign * fr.qpos  # how far out it is now
    g = plan_grasp(s, obj, None, away_from_drawer(s, obj, joint, attempt))  # (as it stands now)
    overhang = palm_overhang(s, obj, joint, g)
    dist = min(uncover_distance(ctx, obj, joint, overhang), out)
    ctx.begin("close", Conjunct(Predicate.CLOSE, region), region)
    yield from push_in(ctx, joint, dist)
    covered = checks.overhanging_drawer(s, obj, pad=0.0) is not None
    if ctx.truth is not None:
        ctx.end(Outcome.HALF_OPEN if covered else Outcome.ACHIEVED, f"{joint} at {env.joint_frame(joint).qpos:.3f}")
    if covered:
        return
    sweep = checks.drawer_sweep(s, joint)
    # aside: grasped from the side away from the drawer, put down near where it is (it goes
    # into the drawer next: its own place does not repel the spot; not farther out than
    # `free_spot` looks: measured, lowering it 0.74 m out took 60 steps). The fist holds
    # nothing and opens on the way: no `free_hand` (a separate opening costs 8-12 steps)
    yield from grasp(ctx, obj, None, choice=away_from_drawer(s, obj, joint, attempt),
                     hover_m=0.08 + 0.03 * min(attempt, 2))
    if checks.held(s) != obj:
        return
    spot = beyond_sweep(s, obj, joint, sweep, overhang)
    if spot is None:
        spot = checks.free_spot(s, obj, goal_points(ctx, obj), [sweep])
    if spot is None:
        raise GiveUp(GiveUpReason.NO_PLAN, f"no free spot on the table to put {obj} aside")
    yield from place_at(ctx, obj, spot)
    if sweep is not None and checks.under_sweep(s, obj, sweep):
        return  # still in the way: the planner decides again
    ctx.begin("open", Conjunct(Predicate.OPEN, region), region)
    if sign * env.joint_frame(joint).qpos < FIST_ROOM_M:
        yield from pull_drawer(ctx, joint, reach_speed=REACH_SPEED, pull_speed=PULL_SPEED)
    else:
        # close the fist while rising off the set-aside object (drag_out closes it standing still)
        yield ctx.move(s.eef() + [0, 0, 0.06], gripper=1.0, yaw=ctx.yaw_hold, tol=0.02, max_steps=12, label="fist")
        yield from drag_out(ctx, joint)
    if ctx.truth is not None:
        ctx.end(Outcome.ACHIEVED if env.object_state(region).is_open() else Outcome.HALF_OPEN,
                f"{joint} at {env.joint_frame(joint).qpos:.3f}")
