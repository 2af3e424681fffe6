"""Restore a saved scene into a built environment and check it physically.

Inputs: a `SimEnv` built from the scene's BDDL and the scene's flattened state. Outputs:
problem strings naming the state file. Invariants: restoring is exact (the state read back
equals the file bit for bit); the gripper's command ramp, which the MuJoCo state lacks, is
set from the finger opening (nearly fully open -> open, else closed: a partly closed
gripper was commanded closed, usually around an object), so a held object stays held.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.sim import SimEnv, TaskSpec, get_task

# the Panda's fingers open to about 0.078 m; anything clearly below was commanded closed
OPEN_GRIPPER_M = 0.07


def scene_task(suite: str, task: str, instruction: str, bddl: Path) -> TaskSpec:
    """The task a scene belongs to, with the model built from the scene's own BDDL file."""
    try:
        return get_task(suite, task).model_copy(update={"bddl_path": Path(bddl)})
    except KeyError:  # a task outside LIBERO's registry: the BDDL alone defines the model
        return TaskSpec(suite=suite, index=-1, name=task, instruction=instruction,
                        bddl_path=Path(bddl), init_states_path=Path(bddl))


def restore_scene(env: SimEnv, state: np.ndarray) -> None:
    env.reset_to(state)
    env.hold_gripper(closed=env.gripper_opening() < OPEN_GRIPPER_M)


def check_restores(env: SimEnv, state: np.ndarray, path: Path) -> list[str]:
    try:
        restore_scene(env, state)
    except ValueError as e:  # a state the model rejects (`SimEnv.reset_to`); anything else sets the scene aside
        return [f"{path}: scene does not restore: {type(e).__name__}: {e}"]
    back = env.get_state()
    if not np.array_equal(back, state):
        worst = int(np.argmax(np.abs(back - state)))
        return [f"{path}: restored state differs from the file (first at index {worst})"]
    return []


def check_goal_unsatisfied(env: SimEnv, path: Path) -> list[str]:
    """A failure scene must have G(s_f) = 0; call right after `restore_scene`."""
    if env.goal_satisfied():
        goal = " and ".join("(" + " ".join(c) + ")" for c in env.goal)
        return [f"{path}: the task goal {goal} already holds in this scene; a failure state must not satisfy it"]
    return []


def max_settle_motion(env: SimEnv, steps: int) -> tuple[float, str | None]:
    """Largest object displacement (m) over `steps` zero-action steps, and which object."""
    joints = env.free_joints()
    start = {n: env.get_state()[1 + a : 4 + a].copy() for n, a in joints.items()}
    worst, who = 0.0, None
    for _ in range(steps):
        env.step(np.zeros(7))
        qpos = env.get_state()[1:]
        for n, a in joints.items():
            d = float(np.linalg.norm(qpos[a : a + 3] - start[n]))
            if d > worst:
                worst, who = d, n
    return worst, who


def check_settled(env: SimEnv, path: Path, steps: int, threshold_m: float) -> list[str]:
    """No object moves more than `threshold_m` in `steps` zero-action steps (after restore)."""
    worst, who = max_settle_motion(env, steps)
    if worst > threshold_m:
        return [
            f"{path}: scene is not settled: {who} moved {worst * 1000:.1f} mm in {steps} "
            f"zero-action steps (limit {threshold_m * 1000:.1f} mm)"
        ]
    return []
