"""Skill: put a held book (a thin upright slab) into a narrow open-topped compartment.

Input: a `Ctx` whose hand holds `obj`, and a region `target` (e.g. a desk caddy's front
compartment, 5.7 x 12.9 cm for an 11 x 2.8 cm book). Output: primitives that turn the hand
so the slab's long side runs along the compartment's long side, bring its footprint centre
over the compartment centre (re-measured once above it, margins are ~7 mm), lower it slowly
until its bottom is just above the floor and open. The book is held near its top edge
(`grasps.SLAB_GRIP_BELOW_TOP`) so the fingers stay above the compartment walls.

`slot_alignment` says whether this skill applies: an upright slab, a region that is not a
drawer and has open sky above it (a shelf's roof would stop the descent: shelf.py), and
a footprint that fits the region when aligned with one of its sides.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.grasps import is_upright_slab
from pipeline.policies.scripted.motion import CARRY_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.notes import Note, Outcome
from pipeline.policies.scripted.placement import region_box
from pipeline.policies.scripted.primitives import Grip

FIT_MARGIN = 0.004  # slab edge to compartment wall, each side, at the least
RELEASE_GAP = 0.008  # slab bottom above the compartment floor when the fingers open
ALIGN_TOL = 0.004  # footprint centre error (m) after which a second correction is made


def footprint(corners: np.ndarray) -> tuple[float, float, float, np.ndarray]:
    """(long-axis angle in [0, pi), long length, thin width, centre xy) of a set of corners."""
    xy = corners[:, :2]
    best = None
    for theta in np.linspace(0.0, np.pi, 180, endpoint=False):
        u = np.array([np.cos(theta), np.sin(theta)])
        w = float(np.ptp(xy @ u))
        if best is None or w < best[0]:
            best = (w, theta)
    thin, theta = best
    long_theta = (theta + np.pi / 2) % np.pi
    u = np.array([np.cos(long_theta), np.sin(long_theta)])
    v = np.array([-u[1], u[0]])
    a, b = xy @ u, xy @ v
    centre = u * (a.max() + a.min()) / 2 + v * (b.max() + b.min()) / 2
    return long_theta, float(np.ptp(a)), thin, centre


def has_roof(env, target: str, obj: str) -> bool:
    """Something lies above the region's middle height over its centre (a shelf's roof)."""
    centre, _ = region_box(env, target)
    return env.ray_down(centre[:2], centre[2] + 0.6, centre[2], ignore=obj) is not None


def slot_alignment(ctx: Ctx, obj: str, target: str, size: tuple[float, float] | None = None) -> float | None:
    """World angle the slab's long axis must take to fit `target`, or None when this skill
    does not apply (see the module docstring). `size`: the slab's own (length, thickness)
    to fit instead of its footprint (a book hanging a few degrees off upright: the recovery
    expert's `stand_book`)."""
    s = ctx.scene
    env = s.env
    if not env.is_region(target) or env.region(target).joints or not is_upright_slab(s, obj):
        return None
    if has_roof(env, target, obj):
        return None
    _, half = region_box(env, target)
    theta, length, thin, _ = footprint(env.object_corners(obj))
    if size is not None:
        length, thin = size
    options = []
    for angle, (along, across) in ((0.0, (half[0], half[1])), (np.pi / 2, (half[1], half[0]))):
        if length / 2 + FIT_MARGIN <= along and thin / 2 + FIT_MARGIN <= across:
            options.append(angle)
    if not options:
        return None
    # the one needing the least turn of the hand
    return min(options, key=lambda a: abs(_wrap_half(a - theta)))


def _wrap_half(a: float) -> float:
    """Angle wrapped into [-pi/2, pi/2): a slab's footprint is the same turned by pi."""
    return (a + np.pi / 2) % np.pi - np.pi / 2


def place_in_slot(ctx: Ctx, obj: str, target: str, angle: float) -> Plan:
    """`angle`: from `slot_alignment`."""
    s = ctx.scene
    env = s.env
    centre, half = region_box(env, target)
    theta, _, _, foot = footprint(env.object_corners(obj))
    turn = _wrap_half(angle - theta)
    # of the two hand yaws giving this footprint, the one nearer the wrist's middle
    yaw = min((ctx.yaw_hold + turn, ctx.yaw_hold + turn - np.pi, ctx.yaw_hold + turn + np.pi),
              key=lambda y: (abs(y) > np.pi / 2 + 0.3, abs(y - ctx.yaw_hold)))
    turn = yaw - ctx.yaw_hold
    c, sn = np.cos(turn), np.sin(turn)
    rot = np.array([[c, -sn], [sn, c]])
    eef = s.eef()
    hold = rot @ (eef[:2] - foot)  # grip site from the footprint centre, after the turn
    bottom = eef[2] - s.box(obj).lo[2]  # grip site above the slab's bottom
    floor = s.support_top(centre[:2], 0.005, {obj}, below=centre[2] + half[2])
    off = ctx.noise.place_offset()  # the failure generator's seeded error (zero: none)
    ctx.note(place_offset=[float(v) for v in off])
    aim = centre[:2] + off[:2]
    release = floor + RELEASE_GAP + bottom + off[2]
    radius = 0.5 * float(np.max(s.box(obj).size[:2]))
    walls = s.path_clearance(centre, centre, radius + 0.03, {obj})
    hover_z = max(walls + CARRY_CLEARANCE + bottom, release + 0.05)
    lift_z = max(s.path_clearance(eef, centre, radius, {obj}) + CARRY_CLEARANCE + bottom, hover_z)
    over = np.array([aim[0] + hold[0], aim[1] + hold[1], hover_z])
    yield from travel(ctx, over, yaw, 1.0, lift_z)
    ctx.yaw_hold = yaw
    yield ctx.move(over, gripper=1.0, speed=0.5, yaw=yaw, tol=0.006, rot_tol=0.04, max_steps=60, label="align")
    if s.holding_any() != obj:
        ctx.events.append(Note(Outcome.DROPPED, obj))
        if ctx.truth is not None:
            ctx.truth.end_hand(obj, False)
        return
    # re-measure: the slab may sit in the fingers a little off what was predicted
    err = aim - footprint(env.object_corners(obj))[3]
    if float(np.linalg.norm(err)) > ALIGN_TOL:
        over = s.eef() + [err[0], err[1], 0.0]
        over[2] = hover_z
        yield ctx.move(over, gripper=1.0, speed=0.3, yaw=yaw, tol=0.004, rot_tol=0.04, max_steps=40, label="align")
    goal = np.array([over[0], over[1], release])
    t = ctx.noise.timing()
    ctx.note(release_timing=t)
    early = {"switch_gripper": -1.0, "switch_dist": 0.006 * -t} if t < 0 else {}
    yield ctx.move(goal, gripper=1.0, speed=0.3, yaw=yaw, tol=0.006, max_steps=80, label="lower", **early)
    yield Grip(-1.0, ctx.open_steps + 4 + max(t, 0), label="open")
    yield ctx.move(s.eef() + [0, 0, 0.03], speed=0.3, yaw=yaw, tol=0.01, max_steps=20, label="retreat")
    yield ctx.move(s.eef() + [0, 0, 0.1], yaw=yaw, tol=0.02, label="retreat")


# the placement strategy (see strategies.py): a book turned to a narrow compartment, lowered in
applies = slot_alignment
plan = place_in_slot
