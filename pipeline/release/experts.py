"""The two zero-noise experts a release runs from its scenes, and one attempt from a scene.

`plain` is the scripted expert of stage 1 with every noise knob at zero (the old
certificate, and the "before" of `benchmarks/certify_coverage.py`); `recovery` is the
closed-loop recovery expert (`pipeline.policies.scripted.recovery`), which first restores
the plan's preconditions and may give up with a reason. `attempt` restores a scene, runs
one expert from it and says why it did not finish when it did not: the expert's own
give-up reason, `goal_not_reached` (it finished its plan and holds still, goal false) or
`timeout` (the horizon ran out while it was still working). A run stops as soon as the
expert gave up or has idled for `IDLE_GRACE_STEPS` (nothing more will happen).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pipeline.config import Config, ScriptedNoise
from pipeline.policies.base import Policy
from pipeline.release.scene_physics import restore_scene
from pipeline.rollout import StepInfo, run_episode
from pipeline.sim import SimEnv

PLAIN, RECOVERY = "plain", "recovery"
EXPERTS = (PLAIN, RECOVERY)
TIMEOUT, GOAL_NOT_REACHED = "timeout", "goal_not_reached"
# an object released onto its target may still be settling when the plan ends
IDLE_GRACE_STEPS = 20

# (env, seed, variation) -> a policy ready for `reset(env.task, seed)`
ExpertFactory = Callable[[SimEnv, int, float], Policy]


def plain_expert(cfg: Config) -> Policy:
    """The scripted expert with every noise knob at zero."""
    from pipeline.policies.scripted import make_scripted_policy

    clean = cfg.stage1.policy.scripted.model_copy(update={"noise": ScriptedNoise(), "noise_by_suite": {}})
    return make_scripted_policy(clean, name="scripted-expert")


def recovery_expert(env: SimEnv, seed: int = 0, variation: float = 0.0) -> Policy:
    from pipeline.policies.scripted.recovery import make_recovery_expert

    return make_recovery_expert(env, env.task, seed=seed, variation=variation)


def expert_factory(kind: str, cfg: Config) -> ExpertFactory:
    """A factory per attempt: the recovery expert is built for its env; the plain one is reused."""
    if kind == RECOVERY:
        return recovery_expert
    if kind == PLAIN:
        policy = plain_expert(cfg)
        return lambda env, seed, variation: policy
    raise ValueError(f"unknown expert {kind!r}; choose from {EXPERTS}")


def give_up_reason(policy: Policy) -> str | None:
    reason = getattr(policy, "give_up_reason", None)
    return None if reason is None else str(getattr(reason, "value", reason))


@dataclass(frozen=True)
class Outcome:
    success: bool
    steps: int
    reason: str | None  # None on success


def attempt(env: SimEnv, state: np.ndarray, policy: Policy, seed: int, horizon: int, chunk_size: int,
            on_step: Callable[[StepInfo], None] | None = None, restore: bool = True) -> Outcome:
    """Restore `state` (unless the caller did), run `policy` until success, give-up or horizon."""
    if restore:
        restore_scene(env, state)
    policy.reset(env.task, seed)
    idle = [0]

    def stop() -> bool:
        if give_up_reason(policy) is not None:
            return True
        idle[0] = idle[0] + 1 if getattr(policy, "phase", "") == "idle" else 0
        return idle[0] > IDLE_GRACE_STEPS

    res = run_episode(env, policy, horizon, chunk_size, stop_on_success=True, on_step=on_step, stop=stop)
    if res.success:
        return Outcome(True, res.steps, None)
    reason = give_up_reason(policy)
    if reason is None:
        reason = TIMEOUT if res.steps >= horizon else GOAL_NOT_REACHED
    return Outcome(False, res.steps, reason)
