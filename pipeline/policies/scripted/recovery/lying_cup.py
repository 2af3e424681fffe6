"""Skill: grasp a mug lying on its side by its handle.

A lying mug is wider (~9.5 cm) than the open fingers, its rim faces sideways, and its
mouth is covered from above by its own wall: no top-down rim or whole grasp holds it
(measured, libero_10 LIVING_ROOM_SCENE5: the fingers closed on nothing 4 times out of 4).
Its handle's outer bar is thin and stands off the body: the fingers close across the bar,
horizontally and square to the mug's axis, opened only a little wider than the bar so the
inner finger fits into the handle's hole when the handle lies flat. It is carried and set
down on its side (where its body origin goes) with the hand kept as it grasped, and the
fingers withdraw the way they came in.
Objects are upright in their own frame (LIBERO's convention: local z up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted.hand import closing_axis, closing_yaw
from pipeline.policies.scripted.motion import CARRY_CLEARANCE, HAND_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.placement import place_xy, support_ceiling
from pipeline.policies.scripted.primitives import Grip
from pipeline.policies.scripted.scene import TABLE_MARGIN, Scene

LYING_COS = 0.5  # the object's own up axis within 60 deg of horizontal: lying
BAR_OUT_M = 0.06  # a handle's outer bar stands at least this far off the body's axis
BAR_THIN_M = 0.02  # ... and is thinner than this across the handle's plane
CUP_TALL_M = 0.07  # a handled cup is at least this tall in its own frame
FINGER_GAP_M = 0.014  # fingers opened this much wider than the bar
RAMP_PER_STEP = 0.25  # the gripper's command ramp per control step (robosuite: 0.01 per sim step)
OPEN_M = 0.08  # finger spread fully open
PALM_M = 0.045  # the palm's underside above the grip site
TILT = 0.52  # radians from straight down for a low handle (palm ~2 cm over body and table)


@dataclass(frozen=True)
class HandleGrasp:
    pos: np.ndarray  # grip site (world)
    yaw: float
    opening: float  # finger spread to descend with
    approach: np.ndarray | None = None  # the hand's pointing direction when tilted


def _rot(quat: np.ndarray) -> np.ndarray:
    w, x, y, z = quat
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _handle_bar(scene: Scene, obj: str):
    """(object rotation, bar centre in the object's frame, unit direction from the body's
    axis to the bar in the object's xy, bar half sizes in the object's frame), or None."""
    env = scene.env
    pos, quat = env.object_pose(obj)
    rot = _rot(quat)
    xpos, xmat, aabb = env.body_geom_frames(obj)
    if not len(xpos):
        return None
    # each collision geom's box centre and half size in the object's frame
    centres = np.array([rot.T @ (xpos[g] + xmat[g] @ aabb[g, :3] - pos) for g in range(len(xpos))])
    halves = np.array([np.abs(rot.T @ xmat[g]) @ aabb[g, 3:] for g in range(len(xpos))])
    # a cup stands tall in its own frame, its handle on its side (not at an end: a bottle
    # lying along its own x or y, as the ketchup does, has its cap far out)
    lo, hi = float((centres[:, 2] - halves[:, 2]).min()), float((centres[:, 2] + halves[:, 2]).max())
    if hi - lo < CUP_TALL_M:
        return None
    core = rot.T @ (env.object_com(obj) - pos)  # the body's axis passes (nearly) through the com
    out = np.linalg.norm(centres[:, :2] - core[:2], axis=1)
    bar = int(np.argmax(out))
    if out[bar] < BAR_OUT_M:
        return None
    if not lo + 0.15 * (hi - lo) < centres[bar, 2] < hi - 0.15 * (hi - lo):
        return None
    radial = (centres[bar, :2] - core[:2]) / out[bar]
    across = np.array([-radial[1], radial[0]])  # across the handle's plane, in the object's xy
    if 2 * float(np.abs(halves[bar, :2]) @ np.abs(across)) > BAR_THIN_M:
        return None
    return rot, centres[bar], radial, halves[bar]


def lying(scene: Scene, obj: str) -> bool:
    """`obj`'s own up axis is within 60 degrees of horizontal (LYING_COS): it lies on its side."""
    return bool(abs(_rot(scene.env.object_pose(obj)[1])[2, 2]) <= LYING_COS)


def lying_handle_grasp(scene: Scene, obj: str) -> HandleGrasp | None:
    """The handle grasp of `obj` when it is a handled object lying on its side, else None."""
    pos, quat = scene.env.object_pose(obj)
    axis = _rot(quat)[:, 2]
    if not lying(scene, obj):
        return None
    found = _handle_bar(scene, obj)
    if found is None:
        return None
    rot, centre, radial, half = found
    h_world = rot @ np.array([*radial, 0.0])
    if h_world[2] < -LYING_COS:
        return None  # the handle is under the mug
    c = np.cross(axis, [0.0, 0.0, 1.0])
    c /= np.linalg.norm(c)
    yaw = closing_yaw(c)
    yaw = (yaw + np.pi / 2) % np.pi - np.pi / 2
    bar_world = pos + rot @ centre
    width = 2 * float(half @ np.abs(rot.T @ closing_axis(yaw)))  # the bar across the fingers
    grip = bar_world.copy()
    grip[2] = max(grip[2], scene.table_height() + TABLE_MARGIN)
    approach = None
    if grip[2] + PALM_M < scene.box(obj).hi[2] + 0.01:
        # a handle lying low at the side: the palm, square to the mug, would come down on
        # the body; tilted about the mug's axis (fingertips in, wrist out) it clears both the
        # body and the table
        out = np.array([h_world[0], h_world[1], 0.0])
        out /= max(np.linalg.norm(out), 1e-9)
        approach = -np.sin(TILT) * out + np.array([0.0, 0.0, -np.cos(TILT)])
    return HandleGrasp(pos=grip, yaw=yaw, opening=min(OPEN_M, width + FINGER_GAP_M), approach=approach)


def grasp_by_handle(ctx: Ctx, obj: str, g: HandleGrasp, hover_m: float = 0.08) -> Plan:
    """Hover over the bar, narrow the fingers to `g.opening`, descend, close, lift."""
    s = ctx.scene
    a = np.array([0.0, 0.0, -1.0]) if g.approach is None else g.approach
    lift_z = s.path_clearance(s.eef(), g.pos, 0.06, {obj}) + HAND_CLEARANCE
    hover = g.pos - a * hover_m  # back along the pointing direction: the descent follows it
    yield from travel(ctx, hover, g.yaw, -1.0, lift_z)
    yield ctx.move(hover, yaw=g.yaw, approach=g.approach, tol=0.012, rot_tol=None if g.approach is None else 0.15,
                   max_steps=60, label="hover")
    # the command ramps from open (-1) toward closed (+1); 0 then holds the spread
    steps = int(round((1.0 - g.opening / OPEN_M) * 2 / RAMP_PER_STEP))
    ctx.yaw_hold, ctx.approach_hold = g.yaw, g.approach
    if steps > 0:
        yield Grip(1.0, steps, label="narrow")
    # (not narrowed, fully open: the open command, as any grasp's descent)
    yield ctx.move(g.pos, gripper=0.0 if steps > 0 else -1.0, speed=0.5, yaw=g.yaw, approach=g.approach, tol=0.007,
                   max_steps=50, label="descend")
    yield Grip(1.0, ctx.close_steps, label="close")
    yield ctx.move(s.eef() + [0, 0, 0.1], gripper=1.0, speed=0.6, yaw=g.yaw, approach=g.approach, tol=0.02,
                   label="pick_lift")  # (carried with the hand as it is: see place_by_handle)


def place_by_handle(ctx: Ctx, obj: str, target: str) -> Plan:
    """Set a mug held by its handle down on `target` with the hand as it grasped (tilted or
    not), let go, and withdraw the way the fingers came in: the inner finger is threaded
    through the handle, and a straight retreat of a turned hand lifts the mug again
    (measured: it hung from one finger)."""
    s = ctx.scene
    a = ctx.approach_hold
    down = np.array([0.0, 0.0, -1.0]) if a is None else a
    body = s.env.object_pose(obj)[0]
    box = s.box(obj)
    eef = s.eef()
    hold = eef - body
    bottom = eef[2] - box.lo[2]
    radius = 0.6 * float(min(box.size[0], box.size[1])) / 2
    dest = place_xy(ctx.scene, obj, target)
    foot = dest + (box.centre[:2] - body[:2])
    release_z = s.support_top(foot, radius, {obj}, below=support_ceiling(s.env, target)) + 0.015 + bottom
    carry_z = max(s.path_clearance(box.centre, foot, radius, {obj}) + CARRY_CLEARANCE + bottom, release_z + 0.05)
    goal = np.array([dest[0] + hold[0], dest[1] + hold[1], release_z])
    yaw = ctx.yaw_hold
    if eef[2] < carry_z - 0.015:
        yield ctx.move([eef[0], eef[1], carry_z], gripper=1.0, yaw=yaw, approach=a, tol=0.02, label="lift")
    yield ctx.move([goal[0], goal[1], carry_z], gripper=1.0, yaw=yaw, approach=a, tol=0.015, label="transport")
    yield ctx.move(goal, gripper=1.0, speed=0.5, yaw=yaw, approach=a, tol=0.01, max_steps=60, label="lower")
    yield Grip(-1.0, ctx.open_steps, label="open")
    yield ctx.move(s.eef() - down * 0.07, gripper=-1.0, yaw=yaw, approach=a, tol=0.015, max_steps=25, label="withdraw")
    ctx.approach_hold = None
    yield ctx.move(s.eef() + [0, 0, 0.05], gripper=-1.0, yaw=yaw, tol=0.02, max_steps=20, label="retreat")
