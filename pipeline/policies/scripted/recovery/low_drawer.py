"""Skill: pull open a drawer whose handle bar sits just over the table (KITCHEN_SCENE1's
bottom drawer: 4.6 cm). The plain expert's tilted grip puts the hand's 21 cm housing
across the bar, into the table. Here a fist, pitched to point into the drawer (as
`articulated._push_low_drawer` pushes one shut), comes down into the slot between the bar
and the drawer face and hooks the bar from behind; the fingers are side by side along the
bar, so the pair fits between its posts. Recovery only: the plain expert keeps its grip."""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted import articulated
from pipeline.policies.scripted.motion import Ctx, Plan, travel
from pipeline.policies.scripted.primitives import Grip
from pipeline.sim.facts import JointKind

LOW_HANDLE_M = 0.06  # a handle bar this close over the table leaves no room for the tilted grip
HOOK_PITCH = 0.9  # radians from straight down, towards the drawer: the finger clears the bar above
HOOK_DEPTH_M = 0.015  # how far below its resting height the hook is pressed
TIP_M = 0.01  # the fingertips lie this far past the grip site along the pointing axis


def table_top(ctx: Ctx) -> float:
    try:
        return float(ctx.scene.env.object_boxes("table")[:, 1, 2].max())
    except (KeyError, ValueError):
        return ctx.scene.table_height()


def low_handle(ctx: Ctx, joint: str) -> bool:
    env = ctx.scene.env
    fr = env.joint_frame(joint)
    if fr.kind != JointKind.SLIDE:
        return False
    pull = fr.axis * articulated.open_sign(fr.range)
    box, _, _ = articulated.handle_box(env, joint, pull)
    return (box[0, 2] + box[1, 2]) / 2 < table_top(ctx) + LOW_HANDLE_M


def hook_low_drawer(ctx: Ctx, joint: str) -> Plan:
    s, env = ctx.scene, ctx.scene.env
    fr = env.joint_frame(joint)
    sign = articulated.open_sign(fr.range)
    pull = fr.axis * sign
    pull = pull / np.linalg.norm(pull)
    box, k, d = articulated.handle_box(env, joint, pull)
    panel = articulated.front_panel(env, joint, k, d)
    face = panel[1, k] if d > 0 else panel[0, k]
    back = box[0, k] if d > 0 else box[1, k]  # the bar's inner face
    pos = (box[0] + box[1]) / 2
    pos[k] = (face + back) / 2
    pos[2] = (box[0, 2] + box[1, 2]) / 2
    yaw = np.pi / 2 if k == 1 else 0.0  # closing axis along the bar
    point = articulated.fist_into(pull, HOOK_PITCH)
    ctx.yaw_hold = yaw
    if s.gripper_open():
        yield Grip(1.0, ctx.close_steps, label="make_fist")
    site = pos - point * TIP_M
    # pitch well out in front, then come in between this bar and the one above, then down
    hover = site + pull * 0.06 + [0, 0, 0.07]
    yield from travel(ctx, hover + [0, 0, 0.08], yaw, 1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
    ctx.approach_hold = point
    yield ctx.move(hover + [0, 0, 0.08], gripper=1.0, yaw=yaw, approach=point, tol=0.01, rot_tol=0.15, max_steps=40,
                   label="pitch")
    yield ctx.move(hover, gripper=1.0, speed=0.6, yaw=yaw, approach=point, tol=0.008, max_steps=40, label="lower")
    over = site + [0, 0, box[1, 2] - pos[2] + 0.02]
    yield ctx.move(over, gripper=1.0, speed=0.4, yaw=yaw, approach=point, tol=0.006, max_steps=40, label="over_bar")
    # aim under the bar's top (the fingertips rest on its back edge otherwise) and keep
    # pressing down while pulling: a level pull lets the tips ride up over the bar
    # (so the move never meets its tolerance: it ends on max_steps)
    yield ctx.move(site - [0, 0, HOOK_DEPTH_M], gripper=1.0, speed=0.4, yaw=yaw, approach=point, tol=0.006,
                   max_steps=15, label="into_slot")
    u = sign * env.joint_frame(joint).qpos  # how open it is now
    full = float(np.max(np.abs(fr.range)))
    target = s.eef() + pull * (full - u + 0.01) - [0, 0, HOOK_DEPTH_M]
    yield ctx.move(target, gripper=1.0, speed=0.5, yaw=yaw, approach=point, tol=0.01, max_steps=60, label="pull")
    yield ctx.move(s.eef() + [0, 0, 0.08], gripper=1.0, yaw=yaw, approach=point, tol=0.02, max_steps=30,
                   label="lift_out")
    ctx.approach_hold = None
    ctx.yaw_hold = 0.0
