"""Skill: unwind a wrist pinned at its joint limit by taking the arm to its home joints.

A wrist joint at its limit (joint 6 at 3.75 rad with joint 5 flipped by ~2.6 rad after a
failing rollout) cannot be freed by moving the hand: the controller works in the hand's
space and keeps the arm on the same side of the wrist's singularity, so the hand stays
tilted at every position (measured: a Cartesian go-home and a half turn of the hand both
left the tilt at 10 deg). The skill follows the straight joint-space path to the home joints
instead, as hand poses computed along it (forward kinematics); the controller then passes
the singularity the way the path does, and the arm arrives at its start pose (~40 steps).
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.recovery import checks

STEP_RAD = 0.35  # most joint travel between two waypoints of the path
RISE_M = 0.05  # a hand that touches something or sits low rises this much first
WAYPOINT_STEPS = 8  # steps per waypoint (the controller lags it; the next one carries on)


def unwind(ctx: Ctx) -> Plan:
    s = ctx.scene
    env = s.env
    grip = 1.0 if checks.held(s) else -1.0  # (a hand closed on nothing opens on the way)
    if checks.arm_in_contact(s, checks.held(s)) or checks.low_hand(s):
        # straight up at the hand's own orientation: turning toward the pinned side holds it
        # in place (measured: a plain back-off stalled 33 of its 40 steps)
        eef, rot = env.eef_pose()
        yield ctx.move(eef + [0.0, 0.0, RISE_M], gripper=grip, orient=rot, tol=0.015, max_steps=15, label="unwind_rise")
    q0 = env.arm_joints()[0]
    home = env.arm_home()
    n = max(2, int(np.ceil(float(np.max(np.abs(home - q0))) / STEP_RAD)))
    for k in range(1, n + 1):
        pos, rot = env.eef_pose_at(q0 + (home - q0) * k / n)
        last = k == n
        yield ctx.move(pos, gripper=grip, orient=rot, tol=0.03 if last else 0.02, rot_tol=0.1,
                       max_steps=3 * WAYPOINT_STEPS if last else WAYPOINT_STEPS, label="unwind")
    ctx.yaw_hold, ctx.approach_hold = 0.0, None  # the home pose: pointing down at yaw 0
