"""The closed-loop recovery expert: from any settled state of a task it reads the live
scene, restores the plan's preconditions (let go of a wrong object, back the arm out,
move obstructions aside, re-open or re-close parts) and runs the task, replanning after
every skill; when it cannot, it stops with a `GiveUpReason`.

    policy = make_recovery_expert(env, task, seed=0, variation=0.0)
    policy.reset(task, seed); run_episode(env, policy, ...)
    policy.give_up_reason  # None, or why it stopped (see also `reason_after(success)`)

Skills, one per file: `pick_place` (pose-aware grasp, different on retry, fingers clear of
neighbours; `long_grasp` slides a lying long object's grasp clear of the palm), `stand_book`
(a leaning book picked up by its top edge with a tilted hand and turned upright in the hand,
then slotted by its own size; a side-lying one turned a quarter at a time first),
`face_book` (one lying on a face pinched by a top corner and stood up), `tip_book` (one
standing upside down pushed over onto a face first), `operate`
(drawers, doors, knobs), `put_aside`, `back_out`, `unwind` (a wrist pinned at its joint
limit: the joint path to the home joints), and the shared `scripted.insert` (into a
roofed container through its door, e.g. a mug into the microwave); `checks` reads the
scene; `planner` decides; `expert` is the `Policy`.
"""

from __future__ import annotations

from pipeline.policies.scripted.recovery.expert import RecoveryExpert
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason
from pipeline.sim import SimEnv, TaskSpec


def make_recovery_expert(
    env: SimEnv | None, task: TaskSpec, seed: int = 0, variation: float = 0.0, budget_steps: int | None = None
) -> RecoveryExpert:
    """A recovery expert for `task`, reset with `seed` (call `reset` again per episode).
    `variation` in [0, 1]: seeded variation of approach and speed (0 = zero noise).
    `env` is accepted for symmetry with callers that hold one; the expert reads the live
    scene from each observation (`obs.sim`)."""
    policy = RecoveryExpert(variation=variation, budget_steps=budget_steps)
    policy.reset(task, seed)
    return policy


__all__ = ["GiveUp", "GiveUpReason", "RecoveryExpert", "make_recovery_expert"]
