"""Skill: press a bowl that leans in an open drawer flat with a fist.

A bowl leaning on a drawer's wall rises over it and jams the drawer as it closes. Re-placing
it means grasping it again: with its back half under the cabinet, even with the drawer fully
out, the hand came down on the cabinet twice (tunewide, libero_10's bottom drawer, init 3);
or it is set aside on the table and put in again, ~200 steps (tunerecur, init 0). Both timed
out. Its highest rim point lies by the wall it leans on, in the open: pressed down there,
the bowl turns flat onto the floor (those two scenes: 35 and 20 degrees of tilt, flat after
one press, the drawer then closed, certified at steps 174 and 509). A bowl standing on its
rim (79 degrees, tunerecur init 2) does not turn under a press: not `leaning`, not pressed.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.grasps import rim
from pipeline.policies.scripted.motion import Ctx, Plan, travel
from pipeline.policies.scripted.primitives import Grip

RIM_INSET_M = 0.015  # the fist lands this far in from the rim's outer edge
OVER_M = 0.06  # the fist comes over the rim point this high
PRESS_BELOW_M = 0.005  # ... and presses to just under where the rim lies once flat (the fist stops there)


def press_flat(ctx: Ctx, obj: str, joint: str) -> Plan:
    """Close the hand, come over `obj`'s highest rim point and press it down to just under
    the height its rim has lying flat on the floor of slide `joint`'s drawer, then rise."""
    r = rim(ctx.scene, obj)
    p = r.highest(RIM_INSET_M)
    floor = float(ctx.scene.env.joint_part_boxes(joint)[:, 1, 2].min())  # the floor plate's top: the lowest part top
    down = floor + r.height - PRESS_BELOW_M
    over = np.array([p[0], p[1], p[2] + OVER_M])
    yield Grip(1.0, ctx.close_steps, label="make_fist")
    yield from travel(ctx, over, ctx.yaw_hold, 1.0, over[2])
    yield ctx.move([p[0], p[1], down], gripper=1.0, yaw=ctx.yaw_hold, speed=1.0, tol=0.01, max_steps=20, label="press")
    yield ctx.move(over, gripper=1.0, yaw=ctx.yaw_hold, tol=0.02, max_steps=30, label="rise")
