"""Skill: back the arm out of contact and out of awkward poses before a new approach.

Up first (out of whatever it touches, keeping the gripper as it is), then, if the pose
is awkward (a joint near its limit, the hand far out or tilted), over to a home pose
above the table centre with the hand pointing down. A nearly straight elbow (the hand
near full reach) is pulled in toward the base before anything rises: rising first
stretches it into its limit, where the controller cannot bring the hand back.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.motion import HAND_CLEARANCE, Ctx, Plan
from pipeline.policies.scripted.primitives import Grip
from pipeline.policies.scripted.recovery import checks

PULL_IN_M = 0.12  # horizontal pull toward the base of a nearly straight arm


def let_go(ctx: Ctx) -> Plan:
    """Open a gripper that holds nothing useful and back off: up, and toward the base as
    much as up when the arm is nearly straight (straight up would lock the elbow)."""
    s = ctx.scene
    if s.gripper_open():
        return
    yield Grip(-1.0, ctx.open_steps + 4, label="release")
    pull = checks.toward_base(s, 0.06) if checks.elbow_straight(s) else np.zeros(3)
    yield ctx.move(s.eef() + pull + [0, 0, 0.06], tol=0.02, max_steps=40, label="back_off")


def back_out(ctx: Ctx) -> Plan:
    s = ctx.scene
    held = checks.held(s)
    grip = 1.0 if held else -1.0
    if checks.arm_in_contact(s, held) or checks.low_hand(s):
        eef = s.eef()
        up = max(eef[2] + 0.05, s.table_height() + checks.SAFE_Z)
        # a nearly straight arm rises while pulling in, so the elbow bends instead of locking
        eef = eef + (checks.toward_base(s, 0.5 * PULL_IN_M) if checks.elbow_straight(s) else 0.0)
        yield ctx.move([eef[0], eef[1], up], gripper=grip, speed=0.5, yaw=ctx.yaw_hold,
                       approach=ctx.approach_hold, tol=0.02, max_steps=40, label="back_out")
    if checks.awkward_arm(s):
        if checks.elbow_straight(s):
            eef = s.eef() + checks.toward_base(s, PULL_IN_M)
            yield ctx.move(eef, gripper=grip, yaw=ctx.yaw_hold, approach=ctx.approach_hold, tol=0.03,
                           max_steps=30, label="pull_in")
        home = checks.robot_base(s)[:2] + checks.HOME_XY
        eef = s.eef()
        clear = s.path_clearance(eef, np.array([*home, 0.0]), 0.05, {held} if held else set()) + HAND_CLEARANCE
        ctx.yaw_hold, ctx.approach_hold = 0.0, None
        # across no lower than the hand is (and clear of what lies between); the next skill
        # lifts and turns the hand as it needs (measured: waiting here for the exact home
        # pose and orientation cost ~100 steps per recovery, often without reaching it)
        yield ctx.move(np.array([home[0], home[1], max(eef[2], clear, s.table_height() + checks.SAFE_Z)]),
                       gripper=grip, tol=0.05, max_steps=40, label="go_home")
