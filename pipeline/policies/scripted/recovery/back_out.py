"""Skill: back the arm out of contact and out of awkward poses before a new approach.

Up first (out of whatever it touches, keeping the gripper as it is), then, if the pose
is awkward (a joint near its limit, the hand far out or tilted), over to a home pose
above the table centre with the hand pointing down.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.skills import Ctx, Plan


def back_out(ctx: Ctx) -> Plan:
    s = ctx.scene
    held = s.holding_any()
    grip = 1.0 if held else -1.0
    if checks.arm_in_contact(s, held) or checks.low_hand(s):
        eef = s.eef()
        up = max(eef[2] + 0.05, s.table_height() + checks.SAFE_Z)
        yield ctx.move([eef[0], eef[1], up], gripper=grip, speed=0.5, yaw=ctx.yaw_hold,
                       approach=ctx.approach_hold, tol=0.02, max_steps=40, label="back_out")
    if checks.awkward_arm(s):
        home = checks.robot_base(s)[:2] + checks.HOME_XY
        z = max(s.eef()[2], s.table_height() + 0.25)
        ctx.yaw_hold, ctx.approach_hold = 0.0, None
        yield ctx.move(np.array([home[0], home[1], z]), gripper=grip, tol=0.03, rot_tol=0.2,
                       max_steps=80, label="go_home")
