"""Check that `FastStepper` and robosuite's `env.step` agree bit for bit on an episode.

One environment plays the same actions twice from the same init state, once through each
stepper; `compare` reports the first step whose flattened state or goal flag differs.
Actions come from a list (random actions) or from a policy run through robosuite's step
(the scripted expert with noise), whose actions are then replayed through the fast step:
identical states make a closed-loop policy choose identical actions, so the replay is the
same episode. Used by tests/sim/test_fast_step.py and benchmarks/step_identity.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.sim.env import SimEnv


@dataclass
class Comparison:
    steps: int
    first_state_mismatch: int | None  # 0-based step index, None when all equal
    first_goal_mismatch: int | None
    successes: int  # steps after which the goal held (robosuite's flags)

    @property
    def identical(self) -> bool:
        return self.first_state_mismatch is None and self.first_goal_mismatch is None


def _play(env: SimEnv, init: int, actions: np.ndarray, fast: bool) -> tuple[np.ndarray, np.ndarray]:
    env.fast_step = fast
    env.reset_to_init(init)
    states, goals = [], []
    for a in actions:
        goals.append(env.step(a))
        states.append(env.get_state())
    return np.array(states), np.array(goals)


@dataclass
class Played:
    actions: np.ndarray
    states: np.ndarray  # after each step
    goals: np.ndarray


def expert_episode(env: SimEnv, policy, init: int, steps: int, seed: int, chunk: int = 8) -> Played:
    """What `policy` does over `steps` steps from init state `init`, robosuite stepping."""
    from pipeline.rollout import run_episode

    fast_before = env.fast_step
    env.fast_step = False
    env.reset_to_init(init)
    policy.reset(env.task, seed)
    actions, states, goals = [], [], []

    def on_step(info) -> None:
        actions.append(info.action)
        states.append(env.get_state())
        goals.append(info.goal)

    try:
        run_episode(env, policy, steps, chunk, stop_on_success=False, on_step=on_step)
    finally:
        env.fast_step = fast_before
    return Played(np.array(actions), np.array(states), np.array(goals))


def expert_actions(env: SimEnv, policy, init: int, steps: int, seed: int, chunk: int = 8) -> np.ndarray:
    return expert_episode(env, policy, init, steps, seed, chunk).actions


def compare(env: SimEnv, init: int, actions: np.ndarray, reference: Played | None = None) -> Comparison:
    """Play `actions` through the fast step and compare with robosuite's step playing them
    (played here unless `reference` holds that run already)."""
    fast_before = env.fast_step
    try:
        if reference is None:
            ref_s, ref_g = _play(env, init, actions, fast=False)
        else:
            ref_s, ref_g = reference.states, reference.goals
        new_s, new_g = _play(env, init, actions, fast=True)
    finally:
        env.fast_step = fast_before
    bad_s = np.flatnonzero(~(ref_s.view(np.int64) == new_s.view(np.int64)).all(axis=1))  # bits, not ==
    bad_g = np.flatnonzero(ref_g != new_g)
    return Comparison(
        steps=len(actions),
        first_state_mismatch=int(bad_s[0]) if len(bad_s) else None,
        first_goal_mismatch=int(bad_g[0]) if len(bad_g) else None,
        successes=int(ref_g.sum()),
    )
