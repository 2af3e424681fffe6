"""Skill: grasp a lying long object beside the robot's base with the hand pitched back toward it.

A grip site too near the shoulder (`reach.underreach`) folds the elbow onto its limit with the
hand pointing down: the hand stalls 3-6 cm short and off to the side, and the transport and
the hover above the object each wait out their step limit there (LIVING_ROOM's baskets and
trays, whose base stands nearer the objects than the kitchens': two missed grasps and ~160
idle steps per attempt). `long_grasp.slide_clear` slides the grasp out along the object
first; where that is not enough (the object's far end is near too), the hand pitches
PITCH about the fingers' closing axis, toward the base's side, fingertips in and wrist out:
the wrist, ~21 cm behind the grip site, then sits ~12 cm further out and the elbow keeps its
bend, and the fingers still close level across the object. Only when that side is within
60 deg of the way to the base (the object lies pointing roughly at the base, as the bottles
there do).

Input: a `Ctx`, the object, the (slid) top-down `Grasp`. Output: primitives that hover back
along the pitched pointing direction, descend along it, close and lift, the hand held pitched
(`ctx.approach_hold`): the object is set down as held (`lying_cup.place_by_handle`), since
levelling the hand would turn it by the pitch in the fingers.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.hand import Grasp, closing_axis
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.reach import underreach
from pipeline.policies.scripted.recovery.lying_cup import OPEN_M, HandleGrasp, grasp_by_handle
from pipeline.policies.scripted.scene import Scene

PITCH = np.radians(35.0)  # hand pitched this far from pointing down, toward the base
TOWARD_BASE = np.cos(np.radians(60.0))  # the pitch's level part at least this near (cosine) the way to the base
HOVER_M = 0.08  # hover back along the pointing direction


def pitched_approach(scene: Scene, g: Grasp) -> np.ndarray | None:
    """The pitched pointing direction for top-down grasp `g` when its grip site is too near
    the shoulder: pitched about the fingers' closing axis (so they still close level across
    the object), toward the side of the base, when that side is within TOWARD_BASE of the way
    to the base; else None."""
    if g.rim or underreach(scene.env, g.pos) <= 0.0:
        return None
    to_base = scene.env.robot_base()[:2] - g.pos[:2]
    n = float(np.linalg.norm(to_base))
    if n < 1e-6:
        return None
    c = closing_axis(g.yaw)
    u = np.array([c[1], -c[0], 0.0])  # level, square to the closing axis
    toward = float(u[:2] @ to_base) / n
    if toward < 0.0:
        u, toward = -u, -toward
    if toward < TOWARD_BASE:
        return None
    return np.cos(PITCH) * np.array([0.0, 0.0, -1.0]) + np.sin(PITCH) * u


def pitched_grasp(ctx: Ctx, obj: str, g: Grasp, approach: np.ndarray) -> Plan:
    """Hover back along `approach`, descend along it, close, lift: the tilted grasp of a mug's
    handle (`lying_cup.grasp_by_handle`), with the fingers fully open."""
    yield from grasp_by_handle(ctx, obj, HandleGrasp(pos=g.pos, yaw=g.yaw, opening=OPEN_M, approach=approach),
                               hover_m=HOVER_M)
