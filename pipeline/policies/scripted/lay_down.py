"""Skill: a tall object into a shallow drawer: stand it at one end, tip it over along the drawer.

Input: a `Ctx` whose hand holds `obj` and a drawer region `target`. LIBERO's `In` tests the
object's body origin against the region box; a standing ketchup bottle (14.6 cm, body at
mid-height) in the white cabinet's top drawer keeps it 1.5 cm above the box (libero_90
task 32), however well it is put in. Output: primitives that
1. stand the object in the drawer near one end of its long (across-the-slide) axis;
2. push its top with a closed fist towards the other end, so it falls flat along the
   drawer, its body origin then low and inside the box.
Nothing else changes: an object that stands low enough goes in as before (`skills.place`).
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.motion import Ctx, Plan, place_at
from pipeline.policies.scripted.placement import region_box, support_ceiling
from pipeline.policies.scripted.primitives import Grip

WALL_GAP_M = 0.015  # standing footprint this far from the end wall
TIP_PUSH_M = 0.10  # how far the fist pushes the top
FIST_OUT_M = 0.022  # fist centre this far outside the object's face before the push
BELOW_TOP_M = 0.025  # the push this far below the object's top


def too_tall(ctx: Ctx, obj: str, target: str) -> bool:
    """Whether `obj`, standing as it is now on the floor of drawer region `target`, would keep
    its body origin above the region's top."""
    env = ctx.scene.env
    if not env.is_region(target) or not env.region(target).joints:
        return False
    s = ctx.scene
    centre, half = region_box(env, target)
    box = s.box(obj)
    rise = env.object_pose(obj)[0][2] - box.lo[2]  # body origin over the object's bottom
    floor = s.support_top(centre[:2], 0.01, {obj}, below=support_ceiling(env, target))
    return bool(box.size[2] > 2 * max(box.size[:2]) and floor + rise > centre[2] + half[2] - 0.005)


def stand_and_tip(ctx: Ctx, obj: str, target: str) -> Plan:
    s = ctx.scene
    env = s.env
    centre, half = region_box(env, target)
    slide = int(np.argmax(np.abs(env.joint_frame(env.region(target).joints[0]).axis[:2])))
    k = 1 - slide  # the drawer's long axis, across its slide: the object falls along it
    box = s.box(obj)
    body = env.object_pose(obj)[0]
    width = float(box.size[k])
    # 1. stand it near the low end of the long axis, in the middle of the other
    foot = centre[:2].copy()
    foot[k] = centre[k] - half[k] + WALL_GAP_M + width / 2
    xy = foot - (box.centre[:2] - body[:2])
    yield from place_at(ctx, obj, xy, support_ceiling(env, target))
    if s.holding(obj):
        return  # it did not let go: the planner decides again
    # 2. tip it: a closed fist just outside its face, a little under its top, pushed along k
    box = s.box(obj)
    d = np.zeros(3)
    d[k] = 1.0
    at = np.array([*box.centre[:2], box.hi[2] - BELOW_TOP_M])
    at[k] = box.lo[k] - FIST_OUT_M
    yaw = 0.0 if k == 0 else np.pi / 2  # fingers across the push: the fist's wide side meets it
    ctx.yaw_hold = yaw
    yield Grip(1.0, ctx.close_steps, label="make_fist")
    yield ctx.move(at + [0, 0, 0.06], gripper=1.0, yaw=yaw, tol=0.01, rot_tol=0.08, max_steps=60, label="over_top")
    yield ctx.move(at, gripper=1.0, speed=0.5, yaw=yaw, tol=0.008, max_steps=40, label="to_top")
    yield ctx.move(at + d * TIP_PUSH_M, gripper=1.0, speed=0.4, yaw=yaw, tol=0.01, max_steps=40, label="tip")
    yield ctx.move(s.eef() + [0, 0, 0.08], gripper=1.0, yaw=yaw, tol=0.015, max_steps=30, label="rise")


# ---- the placement strategy (see strategies.py) ---------------------------------------------
def applies(ctx: Ctx, obj: str, target: str) -> bool | None:
    """It would stand too high in a shallow drawer."""
    return True if too_tall(ctx, obj, target) else None


def plan(ctx: Ctx, obj: str, target: str, _: bool) -> Plan:
    return stand_and_tip(ctx, obj, target)
