"""A long lying object's grasp slid along its length, clear of what the palm would hit.

`grasps.plan_grasp` grasps a long lying object (a toppled bottle) at its centre of mass,
with the fingers closing across it: only a few yaws fit, so when a tall neighbour (a wine
rack) stands where the palm's ends come down, every candidate stops on it (measured: three
descents stopped 7 cm short on the rack, then the time ran out). Sliding the grasp point a
few centimetres along the object, away from the neighbour, clears the palm; the bottle then
tilts a little in the fingers, which placing copes with. A middle too near the robot's
shoulder (`reach.underreach`: the elbow folds to its limit short of it) is slid away from it
the same way.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.grasps import LONG_M, blocked_depth

from pipeline.policies.scripted.hand import Grasp, closing_axis
from pipeline.policies.scripted.placement import footprint_widths
from pipeline.policies.scripted.reach import underreach
from pipeline.policies.scripted.scene import Scene

BLOCKED_M = 0.01  # the palm's way blocked by more than this: slide the grasp
SHIFTS = (0.015, 0.03, 0.045)  # along the object's length, either way, nearest first
END_MARGIN = 0.035  # the grasp point keeps this far inside the object's ends


def _length(scene: Scene, obj: str, g: Grasp) -> tuple[np.ndarray, np.ndarray] | None:
    """The horizontal direction across `g`'s closing axis and the object's corners' span
    along it, when the object is long that way (None for a rim grasp or a short object)."""
    if g.rim:
        return None
    ax = closing_axis(g.yaw)
    along = np.array([ax[1], -ax[0]])
    span = scene.env.object_corners(obj)[:, :2] @ along
    return (along, span) if float(np.ptp(span)) > LONG_M else None


def slides(scene: Scene, obj: str, g: Grasp) -> list[Grasp]:
    """`g` slid along a long object's length by SHIFTS, either way, nearest first, keeping
    END_MARGIN inside its ends (the palm-box test of nudge.py tries them)."""
    length = _length(scene, obj, g)
    if length is None:
        return []
    along, span = length
    here = float(g.pos[:2] @ along)
    out = []
    for d in SHIFTS:
        for sign in (-1.0, 1.0):
            if span.min() + END_MARGIN <= here + sign * d <= span.max() - END_MARGIN:
                pos = g.pos.copy()
                pos[:2] += along * sign * d
                out.append(Grasp(pos=pos, yaw=g.yaw, rim=False))
    return out


def slide_clear(scene: Scene, obj: str, g: Grasp) -> Grasp:
    length = _length(scene, obj, g)
    if length is None:
        return g
    along, span = length
    top = scene.box(obj).hi[2]

    def judge(pos: np.ndarray) -> tuple[float, bool]:
        """(cost, good enough): centimetres too near the shoulder weigh like centimetres
        of blocked palm; a little blocking is fine, any underreach is not."""
        block, under = blocked_depth(scene, pos, g.yaw, top, skip_tips=True), underreach(scene.env, pos)
        return block + under, block <= BLOCKED_M and under <= 0.0

    cost, ok = judge(g.pos)
    if ok:
        return g
    here = float(g.pos[:2] @ along)
    best = (cost, ok, g)
    for d in SHIFTS:
        for sign in (-1.0, 1.0):
            at = here + sign * d
            if not span.min() + END_MARGIN <= at <= span.max() - END_MARGIN:
                continue
            pos = g.pos.copy()
            pos[:2] += along * sign * d
            cost, ok = judge(pos)
            if cost < best[0] - 1e-3:
                best = (cost, ok, Grasp(pos=pos, yaw=g.yaw, rim=False))
        if best[1]:
            break
    return best[2]


def lying_long(scene: Scene, obj: str) -> bool:
    """A long object lying on its side (a toppled bottle): longer than LONG_M and less
    than half as tall as long."""
    widths = footprint_widths(scene, obj)
    return max(widths) > LONG_M and scene.box(obj).size[2] < 0.5 * max(widths)
