"""Skill: tip a book that stands upside down (on its top edge) over onto a face.

Input: a `Scene` and a book `obj` (`stand_book.book_axes`) whose up axis points down within
UPSIDE_DEG of straight down, its faces standing. Turned by quarters (`stand_book.quarter_turn`)
it takes two turns of ~170 steps each, each held by a corner with the hand pitched 45 deg,
before it is grasped: the attempt ran out of time in 9 of `book_poses.py`'s 12 upside-down
books (version 23). Tipped over, it lies on a face with its top edge where it stood, and
`face_book` stands it up in one turn (version 24: 10 of those 12 certified). Output: primitives that
1. bring the closed fingers down beside its upper part, on the side away from `way`;
2. push it over toward `way` (along its faces' normal), and rise.
`tip_way` chooses the side: the one where the lying book and the hand beside it find free
table (nothing standing there), the one toward the robot's base first.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.hand import closing_yaw_near
from pipeline.policies.scripted.motion import HAND_CLEARANCE, Ctx, Plan, travel
from pipeline.policies.scripted.recovery.face_book import level
from pipeline.policies.scripted.recovery.stand_book import FACES_STAND, BookAxes, book_axes
from pipeline.policies.scripted.scene import Scene

UPSIDE_DEG = 145.0  # up axis this far from vertical or more: upside down (a quarter leaves it too steep)
HAND_OFF_M = 0.022  # closed fingertips this far out from the face they push
HAND_BELOW_TOP_M = 0.025  # ... and this far below the book's highest point
HAND_ROOM_M = 0.02  # the fingertips' spot clear this far around
TIP_PUSH_M = 0.10  # how far the fingers push its upper part
# points of the lying book's footprint that must be free table: out along `way` from its
# standing centre (it falls about its lower edge on that side, its bottom edge swinging out by
# its height), across along its length
LIE_OUT_M = (0.03, 0.07, 0.11, 0.14)
LIE_ACROSS_FRAC = (-0.4, 0.0, 0.4)
FREE_M = 0.005  # a support top this near the table's: free table


def upside_down(scene: Scene, obj: str) -> BookAxes | None:
    """The book's axes when `obj` is a book standing on its top edge; None otherwise."""
    ax = book_axes(scene, obj)
    if ax is None or abs(float(ax.thin[2])) > FACES_STAND:
        return None
    return ax if float(ax.up[2]) < np.cos(np.radians(UPSIDE_DEG)) else None


def tip_way(scene: Scene, obj: str) -> np.ndarray | None:
    """The level unit direction to tip `obj` toward (along its faces' normal), or None when it
    is not upside down or neither side has free table for the lying book and the hand; of two
    free sides, the one toward the robot's base."""
    ax = upside_down(scene, obj)
    if ax is None:
        return None
    thin = level(ax.thin)
    to_base = scene.env.robot_base()[:2] - scene.box(obj).centre[:2]
    ways = sorted((thin, -thin), key=lambda w: -float(w[:2] @ to_base))
    return next((w for w in ways if _free(scene, obj, ax, w)), None)


def _free(scene: Scene, obj: str, ax: BookAxes, way: np.ndarray) -> bool:
    centre = scene.box(obj).centre
    along = level(ax.long)
    table = scene.table_height()
    lying = [centre[:2] + way[:2] * d + along[:2] * f * ax.length for d in LIE_OUT_M for f in LIE_ACROSS_FRAC]
    if any(scene.support_top(p, 0.005, {obj}) > table + FREE_M for p in lying):
        return False
    at = _push_start(scene, obj, way)
    return scene.support_top(at[:2], HAND_ROOM_M, {obj}, below=np.inf) < at[2] - 0.01


def _push_start(scene: Scene, obj: str, way: np.ndarray) -> np.ndarray:
    centre = scene.box(obj).centre
    thick = float(np.ptp(scene.env.object_corners(obj) @ way))
    xy = centre[:2] - way[:2] * (thick / 2 + HAND_OFF_M)
    return np.array([*xy, scene.box(obj).hi[2] - HAND_BELOW_TOP_M])


def tip_over(ctx: Ctx, obj: str, way: np.ndarray) -> Plan:
    """`way`: from `tip_way`, asked in the same state."""
    s = ctx.scene
    ctx.note(tip_book=True)
    at = _push_start(s, obj, way)
    # the closing axis across the push: the closed fingers press along the book's length
    yaw = closing_yaw_near(np.array([-way[1], way[0], 0.0]), ctx.yaw_hold)
    # (the fingers close on the way over: `gripper=1.0` throughout)
    over = at + [0.0, 0.0, 0.06]
    yield from travel(ctx, over, yaw, 1.0, s.path_clearance(s.eef(), over, 0.06, set()) + HAND_CLEARANCE)
    ctx.yaw_hold = yaw
    yield ctx.move(over, gripper=1.0, yaw=yaw, tol=0.01, rot_tol=0.08, max_steps=60, label="over_top")
    yield ctx.move(at, gripper=1.0, speed=0.5, yaw=yaw, tol=0.008, max_steps=40, label="to_top")
    yield ctx.move(at + way * TIP_PUSH_M, gripper=1.0, speed=0.4, yaw=yaw, tol=0.01, max_steps=40, label="tip")
    yield ctx.move(s.eef() + [0.0, 0.0, 0.08], gripper=1.0, yaw=yaw, tol=0.015, max_steps=30, label="rise")
