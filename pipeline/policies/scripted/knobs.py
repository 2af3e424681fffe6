"""Turning a knob (LIBERO's stove): grasp its grip bar, twist the wrist about the knob axis.

Input: a `Ctx` and a `turnon`/`turnoff` conjunct naming a fixture with one hinge joint.
The grip bar is the knob part's highest collision box. The hand yaws with the knob while
its position follows the arc around the joint axis, in 0.2 rad steps, then lets go.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.scripted.articulated import part_joint
from pipeline.policies.scripted.goal import Predicate
from pipeline.policies.scripted.motion import Ctx, Plan, free_hand, travel
from pipeline.policies.scripted.notes import Outcome
from pipeline.policies.scripted.primitives import Grip


def bar_yaw(env, joint: str, geom: int) -> float:
    """Hand yaw that closes the fingers across the grip bar: the bar's long horizontal side
    (from the geom's live orientation, so any stove rotation and knob angle) is where the
    fingers must not close along."""
    rot = env.joint_part_axes(joint)[geom]
    half = env.joint_part_half_sizes(joint)[geom]
    horizontal = [i for i in range(3) if abs(rot[2, i]) < 0.7]
    long_axis = rot[:, max(horizontal, key=lambda i: half[i])]
    a = float(np.arctan2(long_axis[1], long_axis[0]))
    return (a + np.pi / 2) % np.pi - np.pi / 2


def turn_knob(ctx: Ctx, conjunct: tuple[str, ...]) -> Plan:
    """Grasp the knob's grip bar (the part's highest box) and twist the wrist about its axis."""
    s, env = ctx.scene, ctx.scene.env
    joint = part_joint(env, conjunct[1])
    if joint is None:
        raise ValueError(f"{conjunct}: no knob joint in task {env.task.task_id}")
    on = conjunct[0] == Predicate.TURNON
    for _ in range(ctx.max_attempts):
        if s.satisfied(conjunct):
            return
        fr = env.joint_frame(joint)
        q, anchor = fr.qpos, fr.anchor
        spin = float(np.sign(fr.axis[2]))
        goal_q = 0.9 if on else fr.range[0] - 0.05
        boxes = env.joint_part_boxes(joint)
        top = int(np.argmax(boxes[:, 1, 2]))
        grip = boxes[top]
        offset = ctx.noise.grasp_offset() * [0.5, 0.5, 1.0]
        ctx.begin("turn_on" if on else "turn_off", conjunct, conjunct[1])
        ctx.note(grasp_offset=offset)
        pos = (grip[0] + grip[1]) / 2 + offset
        pos[2] = grip[1, 2] - 0.015
        yaw = bar_yaw(env, joint, top)
        ctx.yaw_hold = yaw
        yield from free_hand(ctx)
        hover = pos + [0, 0, 0.08]
        yield from travel(ctx, hover, yaw, -1.0, s.path_clearance(s.eef(), hover, 0.06, set()) + 0.07)
        yield ctx.move(hover, yaw=yaw, tol=0.01, rot_tol=0.08, max_steps=40, label="hover_knob")
        yield ctx.move(pos, speed=0.5, yaw=yaw, tol=0.006, max_steps=40, label="descend_knob")
        yield Grip(1.0, ctx.close_steps, label="grip_knob")
        dq = goal_q - q
        n = max(2, int(np.ceil(abs(dq) / 0.2)))
        start = s.eef()
        for i in range(1, n + 1):
            a = spin * dq * i / n
            c, si = np.cos(a), np.sin(a)
            rel = start[:2] - anchor[:2]
            p = anchor[:2] + np.array([c * rel[0] - si * rel[1], si * rel[0] + c * rel[1]])
            yield ctx.move(
                [p[0], p[1], start[2]], gripper=1.0, speed=0.4, yaw=yaw + a, tol=0.01, rot_tol=0.1,
                max_steps=25, label="twist",
            )
        yield Grip(-1.0, ctx.open_steps, label="let_go")
        ctx.yaw_hold = yaw + spin * dq
        yield ctx.move(s.eef() + [0, 0, 0.08], yaw=ctx.yaw_hold, tol=0.02, label="retreat")
        if ctx.truth is not None:
            q_now = env.joint_frame(joint).qpos
            ctx.end(Outcome.ACHIEVED if s.satisfied(conjunct) else Outcome.NOT_TURNED, f"{joint} at {q_now:.3f}")
