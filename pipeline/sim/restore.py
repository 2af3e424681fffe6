"""The one way a scene is restored: LIBERO's own API plus the state LIBERO leaves out.

`restore(env, state, hold_grasp)` takes a plain LIBERO environment (`ControlEnv`,
`OffScreenRenderEnv`, or `SimEnv`'s own) and a flattened MuJoCo state (time, qpos, qvel).
Every place of this project that starts from a saved state calls it (through
`SimEnv.reset_to`): stage 1, `recover eval`, certification, the recovery demos, the LeRobot
export and `recover verify --replay`; the dataset card prints `restore`'s source, so a user
who follows the card gets the project's first step bit for bit.

Invariant: after `restore`, stepping the same float64 actions with robosuite's `env.step`
gives the same states bit for bit in a fresh environment and in a reused one (soft reset).

The body uses only LIBERO, robosuite and numpy (no project import), so the card can quote
it whole. Three things are not in the flattened state, and each line below sets one:
- the arm controller caches the end-effector pose it last read and reads lazily: after
  `set_init_state` it still holds the pre-restore pose, and the first delta action would be
  applied to that (the arm swings ~13 mm back toward it);
- the Panda gripper ramps its command (`current_action`) across control steps; a fresh
  environment has it at zero; `hold_grasp` sets it to fully closed or fully open from the
  finger opening, so a restored grasp holds (a partly closed gripper was commanded closed);
- MuJoCo's constraint-solver warm start (`qacc_warmstart`) carries over between steps.
"""

import numpy as np


def restore(env, state, hold_grasp=False):
    """Restore a flattened MuJoCo state into a LIBERO environment built on the scene's BDDL."""
    np.random.seed(0)  # LIBERO samples fixture poses (not in the state) from np.random at reset
    env.reset()
    robot = env.robots[0]
    robot.gripper.current_action = np.zeros(robot.gripper.dof)  # a fresh env's gripper ramp
    env.sim.data.qacc_warmstart[:] = 0  # a fresh env's solver warm start
    env.set_init_state(np.asarray(state, dtype=np.float64))
    robot.controller.update(force=True)  # read the restored pose, not the cached one
    robot.controller.reset_goal()
    if hold_grasp:
        fingers = env.sim.data.qpos[robot._ref_gripper_joint_pos_indexes]
        closed = fingers[0] - fingers[1] < 0.07  # the Panda's fingers open to about 0.078 m
        robot.gripper.current_action = np.array([-1.0, 1.0]) * (1.0 if closed else -1.0)
