"""Hand-made failure states for the recovery expert's tests, built in the real simulator:
an object teleported (toppled, onto a target, off the table), a drawer set half open, and
a wrong object grasped by driving the plain expert's own grasp skill."""

from __future__ import annotations

import numpy as np

from pipeline.config import ScriptedNoise
from pipeline.policies.scripted.motion import Ctx, grasp
from pipeline.policies.scripted.noise import Noise
from pipeline.policies.scripted.primitives import emit
from pipeline.policies.scripted.scene import Scene
from pipeline.sim import SimEnv


def start(env: SimEnv, init: int = 0) -> None:
    env.reset_to_init(init)
    env.settle(10)


def set_pose(env: SimEnv, obj: str, pos, quat=None, settle: int = 20) -> None:
    """Teleport a free object (position, and w-x-y-z orientation), then let it settle."""
    sim = env.env.sim
    adr = env.free_joints()[obj]
    sim.data.qpos[adr : adr + 3] = pos
    if quat is not None:
        sim.data.qpos[adr + 3 : adr + 7] = quat
    sim.data.qvel[:] = 0.0
    sim.forward()
    env.settle(settle)


def set_joint(env: SimEnv, joint: str, q: float, settle: int = 10) -> None:
    sim = env.env.sim
    j = sim.model.joint_name2id(joint)
    sim.data.qpos[sim.model.jnt_qposadr[j]] = q
    sim.data.qvel[:] = 0.0
    sim.forward()
    env.settle(settle)


def lying(axis: str = "x") -> np.ndarray:
    """Quaternion (w, x, y, z) of a 90-degree turn about a world axis: upright -> on its side."""
    q = np.zeros(4)
    q[0] = np.cos(np.pi / 4)
    q["xyz".index(axis) + 1] = np.sin(np.pi / 4)
    return q


def grasp_wrong(env: SimEnv, obj: str, max_steps: int = 200) -> None:
    """Drive the plain expert's grasp of `obj` (not the task's object) and stop holding it."""
    ctx = Ctx(scene=Scene(env), noise=Noise(ScriptedNoise(), np.random.default_rng(0)))
    steps = 0
    for prim in grasp(ctx, obj):
        eef, rot = env.eef_pose()
        while not prim.done(eef, rot) and steps < max_steps:
            chunk = emit(prim, eef, rot, 8, ctx.yaw_hold)
            for a in chunk:
                env.step(a)
            prim.steps += len(chunk)
            steps += len(chunk)
            eef, rot = env.eef_pose()


def drive(env: SimEnv, ctx: Ctx, plan, max_steps: int = 300) -> int:
    """Run a skill's primitives (a plan generator over `ctx`) in closed loop; steps taken."""
    steps = 0
    for prim in plan:
        eef, rot = env.eef_pose()
        while not prim.done(eef, rot) and steps < max_steps:
            chunk = emit(prim, eef, rot, 8, ctx.yaw_hold, ctx.approach_hold)
            for a in chunk:
                env.step(a)
            prim.steps += len(chunk)
            steps += len(chunk)
            eef, rot = env.eef_pose()
    return steps
