"""The closed-loop episode runner shared by stage 1, expert benchmarks and evaluation.

Asks the policy for a chunk, executes `chunk_size` actions of it open loop (fewer if the
policy returns fewer), and repeats until the horizon or, optionally, the first success.
Everything else (recording, rendering, perturbation) hooks in through `on_step`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.policies.base import Observation, Policy
from pipeline.sim import SimEnv
from pipeline.sim.env import ACTION_DIM
from pipeline.sim.rotations import mat_to_quat


@dataclass
class StepInfo:
    step: int
    action: np.ndarray
    query: bool  # this step started a new chunk
    goal: bool  # the goal holds after the step


@dataclass
class EpisodeResult:
    steps: int
    success: bool
    first_success_step: int | None


def observe(env: SimEnv, policy: Policy, step: int, context: dict | None = None) -> Observation:
    pos, rot = env.eef_pose()
    quat = mat_to_quat(rot)
    images = {cam: env.render(cam, policy.image_size) for cam in policy.cameras}
    return Observation(
        instruction=env.task.instruction,
        step=step,
        eef_pos=pos,
        eef_quat=quat,
        gripper_qpos=env.gripper_qpos(),
        images=images,
        context=context or {},
        sim=env,
    )


def run_episode(
    env: SimEnv,
    policy: Policy,
    horizon: int,
    chunk_size: int,
    stop_on_success: bool = True,
    on_step: Callable[[StepInfo], None] | None = None,
    context: dict | None = None,
    stop: Callable[[], bool] | None = None,
) -> EpisodeResult:
    """Roll `policy` out from the env's current state (call `env.reset_to` first).
    `stop`, asked after every step, ends the episode early (an expert that gave up)."""
    chunk: np.ndarray = np.empty((0, ACTION_DIM))
    used = 0
    first_success = None
    step = 0
    while step < horizon:
        query = used >= min(chunk_size, len(chunk))
        if query:
            chunk = np.asarray(policy.act(observe(env, policy, step, context)), dtype=np.float64)
            if chunk.ndim != 2 or chunk.shape[1] != ACTION_DIM or len(chunk) == 0:
                raise ValueError(f"policy {policy.name} returned a chunk of shape {chunk.shape}, need (N, 7)")
            used = 0
        action = np.clip(chunk[used], -1.0, 1.0)
        used += 1
        goal = env.step(action)
        if on_step is not None:
            on_step(StepInfo(step=step, action=action, query=query, goal=goal))
        step += 1
        if goal and first_success is None:
            first_success = step
            if stop_on_success:
                break
        if stop is not None and stop():
            break
    return EpisodeResult(steps=step, success=first_success is not None, first_success_step=first_success)
