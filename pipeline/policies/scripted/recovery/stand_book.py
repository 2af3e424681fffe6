"""Skill: pick up a book that leans or lies tilted (not standing on its bottom edge) so that
it hangs upright in the hand, ready for the slot skill (slot.py).

Input: a `Ctx` and an object `obj` that is a book (`book_axes`: a thin slab whose body
origin lies on one of its edges, its bottom: LIBERO's `In` tests that origin) whose up axis
is tilted from vertical. Output: primitives that
1. tilt the open hand so it points down the book's up axis, fingers closing across its
   thickness, above the middle of its top edge;
2. go down along that axis and close on the top edge (as deep as a standing book's grasp,
   `grasps.SLAB_GRIP_BELOW_TOP`);
3. lift, and turn the hand back to pointing straight down: the book turns with it and hangs
   upright, held near its top edge like a standing book grasped from above.
A top-down grasp cannot hold such a book: every horizontal width of a leaning book is wider
than the open fingers, and a rim grasp slips off its faces (measured: 4 of 4 missed).
The hand turns at most `MAX_TILT` from pointing down; a book tilted further (upside down)
is not this skill's (`stand_tilt` is then None).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.policies.scripted.grasps import SLAB_GRIP_BELOW_TOP, SLAB_RATIO, SLAB_THIN_M
from pipeline.policies.scripted.primitives import Grip, axis_angle_matrix
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.skills import HAND_CLEARANCE, Ctx, Plan, travel

UPRIGHT_DEG = 20.0  # up axis within this of vertical: standing, grasped from above as usual
MAX_TILT = np.radians(100.0)  # most the hand is tilted from pointing down
BOTTOM_FRAC = 0.1  # the origin lies within this fraction of the height from one end: a book
BACK_OFF_M = 0.09  # grip site this far up the book's axis from the grasp before going in
LIFT_M = 0.12
SETTLE_STEPS = 10


@dataclass(frozen=True)
class BookAxes:
    up: np.ndarray  # world unit vector from the bottom edge (body origin) to the top edge
    thin: np.ndarray  # world unit normal of its faces
    top_mid: np.ndarray  # world point: middle of the top edge, mid-thickness


def book_axes(scene: Scene, obj: str) -> BookAxes | None:
    """A book's axes from its collision boxes in its body frame, or None when `obj` is not
    book-shaped (a thin slab, long, whose body origin lies at one end of a long side)."""
    env = scene.env
    bid = env.env.obj_body_id[obj]
    pos = np.array(env.env.sim.data.body_xpos[bid])
    rot = np.array(env.env.sim.data.body_xmat[bid]).reshape(3, 3)
    local = (env.object_corners(obj) - pos) @ rot  # corners in the body frame
    lo, hi = local.min(axis=0), local.max(axis=0)
    size = hi - lo
    t = int(np.argmin(size))
    others = [i for i in range(3) if i != t]
    if size[t] >= SLAB_THIN_M or min(size[others]) < SLAB_RATIO * size[t]:
        return None
    # the up axis: the one along which the origin sits at an end (a book's bottom)
    ends = {i: min(abs(lo[i]), abs(hi[i])) / size[i] for i in others}
    u = min(ends, key=ends.get)
    if ends[u] > BOTTOM_FRAC:
        return None
    sign = 1.0 if abs(lo[u]) < abs(hi[u]) else -1.0
    mid = (lo + hi) / 2
    mid[u] = hi[u] if sign > 0 else lo[u]
    return BookAxes(up=rot[:, u] * sign, thin=rot[:, t], top_mid=pos + rot @ mid)


def stand_tilt(scene: Scene, obj: str) -> BookAxes | None:
    """The book's axes when it is a book tilted out of standing that this skill can turn
    upright (tilt over UPRIGHT_DEG, at most MAX_TILT); None otherwise."""
    ax = book_axes(scene, obj)
    if ax is None:
        return None
    tilt = float(np.arccos(np.clip(ax.up[2], -1.0, 1.0)))
    return ax if np.radians(UPRIGHT_DEG) < tilt <= MAX_TILT else None


def _yaw_of(closing: np.ndarray) -> float:
    """Top-down hand yaw whose closing axis (R_z(yaw) y) is the horizontal `closing`."""
    return float(np.arctan2(-closing[0], closing[1]))


def tilted_grasp(ax: BookAxes) -> tuple[float, np.ndarray]:
    """(yaw, approach) of a hand pointing along -up, closing
    across the faces. `hand_orientation(yaw, approach)` is the top-down hand at `yaw` turned
    about the horizontal axis cross(-z, approach); its closing axis must then be `thin`."""
    a = -ax.up
    down = np.array([0.0, 0.0, -1.0])
    h = np.cross(down, a)
    angle = float(np.arccos(np.clip(a @ down, -1.0, 1.0)))
    turn = axis_angle_matrix(h, angle) if np.linalg.norm(h) > 1e-6 else np.eye(3)
    # the fingers are symmetric: of the two ways round, the one nearer the wrist's middle.
    # Turning back to top-down undoes `turn`: the closing axis returns to c0, the yaw stays
    yaw = min((_yaw_of(turn.T @ (sg * ax.thin)) for sg in (1.0, -1.0)), key=abs)
    return yaw, a


def stand_up(ctx: Ctx, obj: str, ax: BookAxes) -> Plan:
    s = ctx.scene
    yaw, approach = tilted_grasp(ax)
    grip = ax.top_mid - ax.up * SLAB_GRIP_BELOW_TOP
    start = grip + ax.up * BACK_OFF_M
    ctx.note(stand_book=True)
    if not s.gripper_open():
        yield Grip(-1.0, ctx.open_steps + 4, label="release")
    lift_z = s.path_clearance(s.eef(), start, 0.06, {obj}) + HAND_CLEARANCE
    yield from travel(ctx, start, yaw, -1.0, max(lift_z, start[2]))
    ctx.yaw_hold, ctx.approach_hold = yaw, approach  # Grip primitives hold this orientation
    try:
        yield ctx.move(start, yaw=yaw, approach=approach, tol=0.006, rot_tol=0.03, max_steps=80, label="tilt")
        yield ctx.move(grip, speed=0.2, yaw=yaw, approach=approach, tol=0.006, max_steps=80, label="edge")
        yield Grip(1.0, ctx.close_steps, label="close")
        up = s.eef() + [0.0, 0.0, LIFT_M]
        yield ctx.move(up, gripper=1.0, speed=0.6, yaw=yaw, approach=approach, tol=0.02, max_steps=50,
                       label="pick_lift")
    finally:
        ctx.approach_hold = None
    yield ctx.move(s.eef(), gripper=1.0, yaw=yaw, tol=0.03, rot_tol=0.06, max_steps=80, label="upright")
    # the book swings on in the fingers for a few steps after the hand stopped turning; the
    # slot skill measures its footprint next
    yield Grip(1.0, SETTLE_STEPS, label="settle")
