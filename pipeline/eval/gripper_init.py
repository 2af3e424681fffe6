"""Initialize the gripper of a restored scene open or fully closed, with actions only.

The Panda gripper's command ramp is not part of the MuJoCo state (see `pipeline.sim.env`),
so a restored scene's gripper has no command yet (a ramp at 0 = half open). We do not
teleport finger joints: we set the command ramp to the condition's end value (otherwise
the first steps of a "closed" start would open the fingers to half way and drop a held
object), execute `steps` control steps with a zero arm delta and the gripper command held
at -1 (open) or +1 (close) so the fingers get there through physics, then re-anchor the
arm controller's goal to the pose reached, so the policy's first delta action starts from
where the arm actually is.

Input: a `SimEnv` right after restore (and perturbation). Output: `GripperInit` with the
end-effector displacement during initialization (to check and record) and the opening.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

COMMAND = {"open": -1.0, "closed": 1.0}


@dataclass(frozen=True)
class GripperInit:
    condition: str
    eef_drift_m: float  # |eef after - eef before| during initialization
    opening: float  # finger-joint distance after initialization (about 0.08 open, ~0 shut)


def init_gripper(env, condition: str, steps: int) -> GripperInit:
    if condition not in COMMAND:
        raise ValueError(f"gripper condition must be one of {sorted(COMMAND)}, got {condition!r}")
    # the restore anchors the controller to the restored pose (pipeline.sim.restore); anchor
    # again in case the scene changed since, or the zero-delta steps would pull toward a stale goal
    env.reanchor_controller()
    start, _ = env.eef_pose()
    env.hold_gripper(closed=condition == "closed")
    env.settle(steps, gripper=COMMAND[condition])
    env.reanchor_controller()
    end, _ = env.eef_pose()
    return GripperInit(condition, float(np.linalg.norm(end - start)), env.gripper_opening())
