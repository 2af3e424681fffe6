"""Skill: get a held book under a low shelf: stand it in front, tip it flat, push it in.

Input: a `Ctx` whose hand holds `obj` (an upright slab) and a roofed region `target` whose
gap is too low for the tilted hand of `shelf.slide_into_shelf` (under a two-layer shelf's
plank: 7 cm). `into` points into the shelf through its open side. Output: primitives that
1. stand the book upright in front of the opening, its thin side facing the shelf;
2. push its top away from the shelf, so it falls flat with its bottom (the body origin the
   `In` predicate tests) towards the shelf;
3. push the lying book by its far edge, fingers spread, into the gap; the hand stays out.
Every step reads the book's live pose.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.hand import closing_yaw_near
from pipeline.policies.scripted.motion import CARRY_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.placement import region_box
from pipeline.policies.scripted.primitives import Grip
from pipeline.policies.scripted.scene import TABLE_MARGIN
from pipeline.policies.scripted.shelf import open_side
from pipeline.policies.scripted.slot import footprint

STAND_OUT_M = 0.10  # book's footprint centre this far in front of the opening when stood up
TIP_PUSH_M = 0.10  # how far the fingers push the book's top to tip it
PUSH_OUT_M = 0.018  # grip site this far outside the opening at the end of the push


def tip_and_push(ctx: Ctx, obj: str, target: str, into: np.ndarray) -> Plan:
    s = ctx.scene
    env = s.env
    centre, half = region_box(env, target)
    across = np.array([-into[1], into[0], 0.0])
    open_face = float(centre[:2] @ into[:2]) - float(np.abs(half[:2]) @ np.abs(into[:2]))
    lateral = float(centre[:2] @ across[:2])
    table = s.table_height()

    # 1. stand it up in front of the opening, thin side towards the shelf
    eef = s.eef()
    theta, _, _, foot = footprint(env.object_corners(obj))
    yaw = closing_yaw_near(into, ctx.yaw_hold)
    turn = yaw - ctx.yaw_hold
    c, sn = np.cos(turn), np.sin(turn)
    hold = np.array([[c, -sn], [sn, c]]) @ (eef[:2] - foot)
    off = ctx.noise.place_offset()  # the failure generator's seeded error (zero: none)
    ctx.note(place_offset=[float(v) for v in off])
    spot = across[:2] * lateral + into[:2] * (open_face - STAND_OUT_M) + off[:2]
    hang = eef[2] - s.box(obj).lo[2]
    down = np.array([spot[0] + hold[0], spot[1] + hold[1], table + hang + 0.012])
    radius = 0.5 * float(np.max(s.box(obj).size[:2]))
    lift_z = s.path_clearance(eef, down, radius, {obj}) + CARRY_CLEARANCE + hang
    yield from travel(ctx, down, yaw, 1.0, max(lift_z, down[2] + 0.04))
    ctx.yaw_hold = yaw
    yield ctx.move(down, gripper=1.0, speed=0.4, yaw=yaw, tol=0.008, rot_tol=0.05, max_steps=50, label="stand")
    yield Grip(-1.0, ctx.open_steps + 4, label="open")
    yield ctx.move(s.eef() + [0, 0, 0.06], yaw=yaw, tol=0.015, max_steps=30, label="retreat")

    # 2. tip it: fingers closed, just on the shelf side of its top, pushed away from the shelf
    yaw = closing_yaw_near(across, yaw)
    ctx.yaw_hold = yaw
    _, _, thin, foot = footprint(env.object_corners(obj))
    top = s.box(obj).hi[2]
    at = np.array([*(foot + into[:2] * (thin / 2 + 0.022)), top - 0.025])
    yield ctx.move(at + [0, 0, 0.06], gripper=1.0, yaw=yaw, tol=0.01, rot_tol=0.08, max_steps=60, label="over_top")
    yield ctx.move(at, gripper=1.0, speed=0.5, yaw=yaw, tol=0.008, max_steps=40, label="to_top")
    yield ctx.move(at - into * TIP_PUSH_M, gripper=1.0, speed=0.4, yaw=yaw, tol=0.01, max_steps=40, label="tip")
    yield ctx.move(s.eef() + [0, 0, 0.08], gripper=1.0, yaw=yaw, tol=0.015, max_steps=30, label="rise")

    # 3. push it in by its far edge, fingers spread across it
    for _ in range(2):  # a second push if the first left it short (it slid aside or stuck)
        corners = env.object_corners(obj)
        along = corners[:, :2] @ into[:2]
        mid = float(corners[:, :2].mean(axis=0) @ across[:2])
        start = across * mid + into * (float(along.min()) - 0.022)
        start[2] = table + TABLE_MARGIN + 0.004
        yield Grip(-1.0, ctx.open_steps, label="spread")
        yield ctx.move(start + [0, 0, 0.08], yaw=yaw, tol=0.012, max_steps=60, label="behind")
        yield ctx.move(start, speed=0.5, yaw=yaw, tol=0.008, max_steps=40, label="down")
        end = across * mid + into * (open_face - PUSH_OUT_M)
        end[2] = start[2]
        yield ctx.move(end, speed=0.35, yaw=yaw, tol=0.008, max_steps=90, label="push")
        yield ctx.move(s.eef() - into * 0.03 + [0, 0, 0.08], yaw=yaw, tol=0.015, max_steps=30, label="rise")
        if s.satisfied(("in", obj, target)):
            return


# the placement strategy (see strategies.py): a gap too low for the tilted hand (shelf.py
# found none high enough): tip the book flat, push it in
applies = open_side
plan = tip_and_push
