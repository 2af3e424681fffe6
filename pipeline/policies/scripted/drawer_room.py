"""Skill: make room in a drawer before something goes in (open it, or open it further).

Input: a `Ctx`, the drawer's region (`white_cabinet_1_bottom_region`) and the object that
must go in. A drawer that is open by LIBERO's predicate can still be too short for the
object: the white cabinet's bottom drawer, 14.6 cm out, leaves no spot where a bowl comes
down clear of both its front wall and the handles of the drawers above it; 1.4 cm more
does. A closed drawer is opened as usual; an open but cramped one is pulled to the end of
its slide from inside: a closed fist lowered just behind the front wall drags it out (no
handle grasp low over the table).
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.articulated import (FINGER_HALF, fist_yaw, front_panel, handle_box, open_sign, open_part,
                                                    part_joint)
from pipeline.policies.scripted.motion import Ctx, Plan, travel
from pipeline.policies.scripted.notes import Outcome
from pipeline.policies.scripted.placement import place_room
from pipeline.policies.scripted.primitives import Grip
from pipeline.sim.facts import JointKind

END_M = 0.005  # a slide this close to the end of its range counts as fully out
PART_WAY_M = 0.1  # out this far (most of the way: a pull stopped short), a fist fits behind the front wall


def cramped(ctx: Ctx, region: str, obj: str) -> bool:
    """An open drawer, short of the end of its slide, with no clear spot for `obj`."""
    env = ctx.scene.env
    joint = part_joint(env, region) if env.is_region(region) else None
    if joint is None or env.joint_frame(joint).kind != JointKind.SLIDE or not env.object_state(region).is_open():
        return False
    fr = env.joint_frame(joint)
    if open_sign(fr.range) * fr.qpos >= float(np.max(np.abs(fr.range))) - END_M:
        return False
    return not place_room(ctx.scene, obj, region)


def part_way_out(env, region: str) -> bool:
    """A drawer pulled out far enough for a fist behind its front wall, but not yet open by
    LIBERO's predicate (a pull stopped short: the tilted hand met something behind it)."""
    joint = part_joint(env, region) if env.is_region(region) else None
    if joint is None or env.joint_frame(joint).kind != JointKind.SLIDE or env.object_state(region).is_open():
        return False
    fr = env.joint_frame(joint)
    return open_sign(fr.range) * fr.qpos >= PART_WAY_M


def finish_opening(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    """Drag a part-way-out drawer to the end of its slide from inside."""
    env = ctx.scene.env
    joint = part_joint(env, conjunct[1])
    ctx.begin("open", conjunct, conjunct[1])
    yield from drag_out(ctx, joint)
    if ctx.truth is not None:
        done = env.object_state(conjunct[1]).is_open()
        ctx.end(Outcome.ACHIEVED if done else Outcome.HALF_OPEN, f"{joint} at {env.joint_frame(joint).qpos:.3f}")


def make_room(ctx: Ctx, conjunct: tuple[str, ...], obj: str) -> Plan:
    """`conjunct` is an implied ("open", region) before `obj` goes into the region."""
    env = ctx.scene.env
    if not env.object_state(conjunct[1]).is_open():
        yield from open_part(ctx, conjunct)
    elif cramped(ctx, conjunct[1], obj):
        ctx.begin("open", conjunct, conjunct[1])
        joint = part_joint(env, conjunct[1])
        yield from drag_out(ctx, joint)
        if ctx.truth is not None:
            ctx.end(Outcome.ACHIEVED if not cramped(ctx, conjunct[1], obj) else Outcome.HALF_OPEN,
                    f"{joint} at {env.joint_frame(joint).qpos:.3f}")


def drag_out(ctx: Ctx, joint: str) -> Plan:
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    sign = open_sign(fr.range)
    pull = fr.axis * sign
    pull = pull / np.linalg.norm(pull)
    box, k, d = handle_box(env, joint, pull)
    panel = front_panel(env, joint, k, d)
    face = panel[1, k] if d > 0 else panel[0, k]
    boxes = env.joint_part_boxes(joint)
    width = boxes[:, 1, 1 - k] - boxes[:, 0, 1 - k]
    floor = float(boxes[:, 1, 2].min())
    # the front wall: the wide upright boxes at the front; its inner face is their innermost side
    outer = np.where(d > 0, boxes[:, 1, k], boxes[:, 0, k])
    front = boxes[(width > 0.6 * width.max()) & (np.abs(outer - face) < 0.03) & (boxes[:, 1, 2] > floor + 0.02)]
    inner = float(front[:, 0, k].min()) if d > 0 else float(front[:, 1, k].max())
    pos = (panel[0] + panel[1]) / 2
    pos[k] = inner - d * (FINGER_HALF + 0.008)
    pos[2] = floor + 0.025  # fingertips about 1.5 cm over the drawer floor
    # the palm's long side along the wall, turned the way that leaves the wrist room (a fixed
    # yaw wound joint 7 onto its limit, and the hand crawled 165 steps to the drawer: measured,
    # libero_90 KITCHEN_SCENE1, a timeout)
    yaw = fist_yaw(ctx, np.pi / 2 if k == 1 else 0.0)
    ctx.yaw_hold = yaw
    # the fist is made before setting off (not on the way, as articulated's pushes): the
    # travel here can be 8 steps, the fingers still open when they went into the drawer
    # (measured: tunebooks, the bottom drawer, three drags and a timeout)
    if s.gripper_open():
        yield Grip(1.0, ctx.close_steps, label="make_fist")
    hover = pos + [0, 0, 0.1]
    yield from travel(ctx, hover, yaw, 1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
    yield ctx.move(pos, gripper=1.0, speed=0.6, yaw=yaw, tol=0.01, max_steps=50, label="into_drawer")
    u = sign * env.joint_frame(joint).qpos
    full = float(np.max(np.abs(fr.range)))
    yield ctx.move(s.eef() + pull * (full - u + 0.01), gripper=1.0, speed=0.5, yaw=yaw, tol=0.006, max_steps=30,
                   label="drag_out")
    yield ctx.move(s.eef() + [0, 0, 0.1], gripper=1.0, yaw=yaw, tol=0.02, max_steps=30, label="retreat")
