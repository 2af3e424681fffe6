"""robosuite's control step with only the work whose results we use: bit for bit the same.

`FastStepper(env).step(action)` does what LIBERO's `env.step(action)` does to the MuJoCo
state and to the goal check, and returns the goal flag. Per 20 Hz control step robosuite
runs 25 substeps of: `mj_forward`, the OSC controller (which calls `mj_forward` again on
the same state, then recomputes Jacobians, mass matrix and action constants), the gripper
ramp, `mj_step`, and 145 observable updates; then a reward, LIBERO's state hooks, a goal
check and an observation dict. Here each substep is:

- `mj_step1`, the position and velocity half of `mj_step`'s forward pass: the controller
  reads kinematics, Jacobians, mass matrix and bias forces of the current state from it.
  robosuite runs a whole `mj_forward` here (whose acceleration and constraint half is
  thrown away: `mj_step` recomputes it with the new controls, and the solver's warm start
  is saved only when the state advances, not by `mj_forward`), then `mj_step`, which
  repeats the position and velocity half. `split=False` keeps robosuite's
  `mj_forward` + `mj_step` (for the benchmark's per-removal figures).
- the controller's own `mj_forward`: dropped (same inputs, same outputs).
- one `mj_jacSite` call for both Jacobians (robosuite calls it four times: position and
  rotation, each for the Jacobian and again for the site velocity).
- OSC math with robosuite's own numba kernels (`opspace_matrices`, `nullspace_torques`,
  `orientation_error`) on arrays of the same layout, so the floats are the same;
  torque limits, gripper control range and index lists read once per controller.
- the Panda gripper's command ramp (`current_action`), kept: it carries over between steps.
- `mj_step2` (the acceleration half and the integration), or `mj_step` when not split.

Dropped entirely: observables (per substep and the final observation dict; nothing of
ours reads them), the reward (a second goal check), the robot's `recent_*` history
buffers (read only by observables and robosuite's own wrappers, never by the state).
Kept after the substeps: `timestep`/`cur_time`, LIBERO's `_post_process` (stove burners'
state) and one `_check_success`, as LIBERO's `step` computes `done`.

The controller's cached state (`ee_pos`, Jacobians, `new_update`, `goal_*`) is kept up to
date exactly as robosuite keeps it, so `reanchor_controller`, a robosuite `env.step` and
this stepper can be mixed freely within an episode.
"""

from __future__ import annotations

import mujoco
import numpy as np


class UnsupportedController(RuntimeError):
    """The environment's controller is not the fixed-impedance delta OSC LIBERO uses."""


try:  # np.clip's own ufunc without its Python wrappers: the same floats, less overhead
    from numpy.core.umath import clip as _clip
except ImportError:  # pragma: no cover
    _clip = np.clip


def _as_slice(index):
    """A slice for a run of consecutive indices (a view, not a gather), else the list."""
    idx = [int(i) for i in np.atleast_1d(index)]
    if idx and idx == list(range(idx[0], idx[0] + len(idx))):
        return slice(idx[0], idx[0] + len(idx))
    return idx


class _Bound:
    """Per-controller constants and views (a soft reset builds a new controller)."""

    def __init__(self, env, robot, controller):
        from robosuite.controllers.osc import OperationalSpaceController
        from robosuite.utils import control_utils

        # robosuite's own (numba) kernels: the same floats as its controller
        self.opspace_matrices = control_utils.opspace_matrices
        self.nullspace_torques = control_utils.nullspace_torques
        self.orientation_error = control_utils.orientation_error

        c = controller
        if not (
            type(c) is OperationalSpaceController and c.impedance_mode == "fixed" and c.use_delta
            and c.use_ori and c.uncoupling and c.interpolator_pos is None and c.interpolator_ori is None
        ):
            raise UnsupportedController(f"fast step supports LIBERO's OSC_POSE only, got {type(c).__name__}")
        from robosuite.models.grippers.panda_gripper import PandaGripper

        if type(robot.gripper) is not PandaGripper:
            raise UnsupportedController(f"fast step supports the Panda gripper only, got {type(robot.gripper).__name__}")
        self.controller = c
        self.sim = env.sim
        self.m = env.sim.model._model
        self.d = env.sim.data._data
        self.site_id = env.sim.model.site_name2id(c.eef_name)
        self.qpos_index = _as_slice(c.qpos_index)  # exact copies either way; slices are cheaper
        self.qvel_index = _as_slice(c.qvel_index)
        self.qvel_list = list(c.qvel_index)
        self.jacp = np.zeros((3, self.m.nv))
        self.jacr = np.zeros((3, self.m.nv))
        self.full_m = np.ndarray(shape=(self.m.nv, self.m.nv), dtype=np.float64, order="C")
        self.kp_pos, self.kp_ori = np.array(c.kp[0:3]), np.array(c.kp[3:6])
        self.kd_pos, self.kd_ori = c.kd[0:3], c.kd[3:6]
        self.torque_low, self.torque_high = robot.torque_limits
        self.arm_actuators = _as_slice(robot._ref_joint_actuator_indexes)
        self.control_dim = c.control_dim
        g = robot.gripper
        self.gripper = g
        self.grip_actuators = _as_slice([env.sim.model.actuator_name2id(a) for a in g.actuators])
        ctrl_range = np.atleast_2d(env.sim.model.actuator_ctrlrange[self.grip_actuators])
        self.grip_bias = 0.5 * (ctrl_range[:, 1] + ctrl_range[:, 0])
        self.grip_weight = 0.5 * (ctrl_range[:, 1] - ctrl_range[:, 0])
        self.grip_sign = np.array([-1.0, 1.0]) * g.speed

    def update(self) -> None:
        """robosuite's `Controller.update` minus its `mj_forward` (the caller just ran one)."""
        c, d = self.controller, self.d
        mujoco.mj_jacSite(self.m, d, self.jacp, self.jacr, self.site_id)
        c.ee_pos = d.site_xpos[self.site_id].copy()
        c.ee_ori_mat = d.site_xmat[self.site_id].reshape(3, 3).copy()
        c.ee_pos_vel = np.dot(self.jacp, d.qvel)
        c.ee_ori_vel = np.dot(self.jacr, d.qvel)
        c.joint_pos = d.qpos[self.qpos_index].copy()
        c.joint_vel = d.qvel[self.qvel_index].copy()
        # robosuite's exact expressions: indexing columns with a list gives Fortran-ordered
        # arrays, and the numba kernels and BLAS round differently for other layouts
        c.J_pos = self.jacp[:, self.qvel_list]
        c.J_ori = self.jacr[:, self.qvel_list]
        c.J_full = np.concatenate((c.J_pos, c.J_ori))  # = np.vstack, layout included
        mujoco.mj_fullM(self.m, self.full_m, d.qM)
        c.mass_matrix = self.full_m[self.qvel_list, :][:, self.qvel_list]
        c.new_update = False

    def torques(self) -> np.ndarray:
        """robosuite's `OperationalSpaceController.run_controller` (fixed, uncoupled, no
        interpolators), same operations in the same order."""
        c = self.controller
        if c.new_update:
            self.update()
        position_error = c.goal_pos - c.ee_pos
        desired_force = position_error * self.kp_pos + (-c.ee_pos_vel) * self.kd_pos
        ori_error = self.orientation_error(c.goal_ori, c.ee_ori_mat)
        desired_torque = ori_error * self.kp_ori + (-c.ee_ori_vel) * self.kd_ori
        # lambda_full (first) only feeds the null-space matrix, computed inside
        _, lambda_pos, lambda_ori, nullspace_matrix = self.opspace_matrices(c.mass_matrix, c.J_full, c.J_pos, c.J_ori)
        decoupled_wrench = np.concatenate([np.dot(lambda_pos, desired_force), np.dot(lambda_ori, desired_torque)])
        torques = np.dot(c.J_full.T, decoupled_wrench) + self.d.qfrc_bias[self.qvel_index]
        torques += self.nullspace_torques(c.mass_matrix, nullspace_matrix, c.initial_joint, c.joint_pos, c.joint_vel)
        c.torques = torques
        c.new_update = True
        return torques


class FastStepper:
    """Steps one LIBERO (robosuite) environment; see the module docstring."""

    def __init__(self, env, split: bool = True):
        self.env = env
        self.split = split
        self._bound: _Bound | None = None
        self.substeps = int(round(env.control_timestep / env.model_timestep))
        if abs(self.substeps * env.model_timestep - env.control_timestep) > 1e-12:
            raise UnsupportedController("control period is not a whole number of physics steps")
        if int(env.control_timestep / env.model_timestep) != self.substeps:
            raise UnsupportedController("robosuite's substep count differs from the rounded one")
        if len(env.robots) != 1:
            raise UnsupportedController("fast step supports one robot")

    def _binding(self) -> _Bound:
        robot = self.env.robots[0]
        b = self._bound
        if b is None or b.controller is not robot.controller or b.sim is not self.env.sim:
            b = self._bound = _Bound(self.env, robot, robot.controller)
        return b

    def step(self, action: np.ndarray) -> bool:
        env = self.env
        if env.done:
            raise ValueError("executing action in terminated episode")
        b = self._binding()
        m, d, c, robot = b.m, b.d, b.controller, env.robots[0]
        arm_action, gripper_action = action[: b.control_dim], action[b.control_dim :]
        grip_delta = b.grip_sign * np.sign(gripper_action)
        env.timestep += 1
        first, second = (mujoco.mj_step1, mujoco.mj_step2) if self.split else (mujoco.mj_forward, mujoco.mj_step)
        for i in range(self.substeps):
            first(m, d)
            if i == 0:
                if c.new_update:
                    b.update()
                c.set_goal(arm_action)  # robosuite's own; its update() is a no-op now
            torques = _clip(b.torques(), b.torque_low, b.torque_high)
            robot.torques = torques
            g = b.gripper
            g.current_action = _clip(g.current_action + grip_delta, -1.0, 1.0)
            d.ctrl[b.grip_actuators] = b.grip_bias + b.grip_weight * g.current_action
            d.ctrl[b.arm_actuators] = torques
            second(m, d)
        env.cur_time += env.control_timestep
        env.done = (env.timestep >= env.horizon) and not env.ignore_done
        env._post_process()
        return bool(env._check_success())
