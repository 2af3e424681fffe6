"""What one 20 Hz control step costs, and what each piece removed by the fast step bought.

    .venv/bin/python benchmarks/step_cost.py [--suite libero_spatial] [--task-index 0] [--steps 200] [--rounds 3]

Plays the same actions (the scripted expert with smoke noise, recorded once) from the same
init state through robosuite's `env.step`, through `FastStepper`, and through variants of
the fast step that add back one removed piece at a time, cumulatively, in this order:

  fast step                 mj_step1 + controller + mj_step2, per substep
  + pre-control mj_forward  robosuite's mj_forward + mj_step in place of mj_step1/mj_step2
  + controller mj_forward   the controller's own, second mj_forward per substep
  + 4 Jacobian calls        robosuite's separate jacp/jacr calls for Jacobians and velocities
  + history buffers         the robot's recent_* buffers pushed at every control step
  + robosuite control       robosuite's `robot.control` itself (constants recomputed per substep)
  + reward                  the reward's extra goal check
  + observables             145 observable updates per step and the observation dict
  robosuite env.step        the real thing, for reference (should match the line above)

and the physics inside: 25 x mj_step (timed inside the step, robosuite's split) and
25 x (mj_step1 + mj_step2) (the fast step's). Each variant runs `--rounds` times,
interleaved; the table gives the median ms per control step. Every variant must leave the
same final state as robosuite's (checked).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.sim import SimEnv, tasks  # noqa: E402
from pipeline.sim.fast_step import FastStepper  # noqa: E402

PIECES = ["pre_forward", "ctrl_forward", "jacobians", "buffers", "robot_control", "reward", "observables"]


class AddBackStepper(FastStepper):
    """FastStepper with the first `level` removed pieces (PIECES order) put back."""

    def __init__(self, env, level: int):
        super().__init__(env, split=level < 1)
        self.on = set(PIECES[:level])

    def _update(self, b) -> None:
        c, sim = b.controller, b.sim
        if "ctrl_forward" in self.on:
            mujoco.mj_forward(b.m, b.d)
        if "jacobians" not in self.on:
            return b.update()
        name = c.eef_name  # robosuite's Controller.update body after its forward
        c.ee_pos = np.array(sim.data.site_xpos[sim.model.site_name2id(name)])
        c.ee_ori_mat = np.array(sim.data.site_xmat[sim.model.site_name2id(name)].reshape([3, 3]))
        c.ee_pos_vel = np.array(sim.data.get_site_xvelp(name))
        c.ee_ori_vel = np.array(sim.data.get_site_xvelr(name))
        c.joint_pos = np.array(sim.data.qpos[c.qpos_index])
        c.joint_vel = np.array(sim.data.qvel[c.qvel_index])
        c.J_pos = np.array(sim.data.get_site_jacp(name).reshape((3, -1))[:, c.qvel_index])
        c.J_ori = np.array(sim.data.get_site_jacr(name).reshape((3, -1))[:, c.qvel_index])
        c.J_full = np.array(np.vstack([c.J_pos, c.J_ori]))
        mujoco.mj_fullM(b.m, b.full_m, sim.data.qM)
        c.mass_matrix = b.full_m[c.qvel_index, :][:, c.qvel_index]
        c.new_update = False

    @staticmethod
    def _buffers(robot, action) -> None:
        from robosuite.utils import transform_utils as T

        c = robot.controller  # robosuite's SingleArm.control, policy-step block
        robot.recent_qpos.push(robot._joint_positions)
        robot.recent_actions.push(action)
        robot.recent_torques.push(robot.torques)
        robot.recent_ee_forcetorques.push(np.concatenate((robot.ee_force, robot.ee_torque)))
        robot.recent_ee_pose.push(np.concatenate((c.ee_pos, T.mat2quat(c.ee_ori_mat))))
        robot.recent_ee_vel.push(np.concatenate((c.ee_pos_vel, c.ee_ori_vel)))
        robot.recent_ee_vel_buffer.push(np.concatenate((c.ee_pos_vel, c.ee_ori_vel)))
        diffs = np.vstack([robot.recent_ee_acc.current, robot.control_freq * np.diff(robot.recent_ee_vel_buffer.buf, axis=0)])
        robot.recent_ee_acc.push(np.array([np.convolve(col, np.ones(10) / 10.0, mode="valid")[0] for col in diffs.T]))

    def step(self, action: np.ndarray) -> bool:
        env, on = self.env, self.on
        b = self._binding()
        m, d, c, robot = b.m, b.d, b.controller, env.robots[0]
        first, second = (mujoco.mj_step1, mujoco.mj_step2) if self.split else (mujoco.mj_forward, mujoco.mj_step)
        grip_delta = b.grip_sign * np.sign(action[b.control_dim:])
        env.timestep += 1
        for i in range(self.substeps):
            first(m, d)
            if "robot_control" in on:
                robot.control(action, policy_step=i == 0)
            else:
                if c.new_update:
                    self._update(b)
                if i == 0:
                    c.set_goal(action[: b.control_dim])
                robot.torques = torques = np.clip(b.torques(), b.torque_low, b.torque_high)
                g = b.gripper
                g.current_action = np.clip(g.current_action + grip_delta, -1.0, 1.0)
                d.ctrl[b.grip_actuators] = b.grip_bias + b.grip_weight * g.current_action
                d.ctrl[b.arm_actuators] = torques
                if i == 0 and "buffers" in on:
                    self._buffers(robot, action)
            second(m, d)
            if "observables" in on:
                env._update_observables()
        env.cur_time += env.control_timestep
        if "reward" in on:
            env.reward(action)
        env._post_process()
        done = bool(env._check_success())
        if "observables" in on:
            env._get_observations()
        return done


def physics_only(env: SimEnv, init: int, actions: np.ndarray, split: bool) -> float:
    """Seconds per control step in the physics calls alone, along the same trajectory:
    the fast step runs, and only its mj_step (or mj_step1 + mj_step2) calls are timed."""
    stepper = FastStepper(env.env, split=split)
    m, d = env.env.sim.model._model, env.env.sim.data._data
    spent = [0.0]
    names = ("mj_step1", "mj_step2") if split else ("mj_forward", "mj_step")
    timed_names = names if split else names[1:]
    originals = {n: getattr(mujoco, n) for n in names}

    def wrap(fn):
        def run(*a):
            t = time.perf_counter()
            fn(*a)
            spent[0] += time.perf_counter() - t
        return run

    env.reset_to_init(init)
    try:
        for n in timed_names:
            setattr(mujoco, n, wrap(originals[n]))
        for a in actions:
            stepper.step(a)
    finally:
        for n, fn in originals.items():
            setattr(mujoco, n, fn)
    return spent[0] / len(actions)


NOISE = dict(grasp_offset_m=0.02, approach_height_m=0.015, gripper_timing_steps=6, action_noise=0.2,
             speed_scale=0.5, place_offset_m=0.03)  # configs/smoke.yaml's


def recorded_expert(env: SimEnv, init: int, steps: int) -> np.ndarray:
    from pipeline.config import ScriptedNoise, ScriptedPolicyConfig
    from pipeline.policies.scripted import make_scripted_policy
    from pipeline.sim.step_check import expert_actions

    policy = make_scripted_policy(ScriptedPolicyConfig(noise=ScriptedNoise(**NOISE)))
    return expert_actions(env, policy, init, steps, 0)


def control_step_costs(task, steps: int = 200, init: int = 0, rounds: int = 3) -> dict[str, float]:
    """Median ms per control step: 'robosuite' (env.step), 'fast', 'mj_step' (the 25 inside
    robosuite's step) and 'split' (the fast step's 25 mj_step1 + mj_step2)."""
    with SimEnv(task) as env:
        actions = recorded_expert(env, init, steps)
        runs: dict[str, list[float]] = {"robosuite": [], "fast": [], "mj_step": [], "split": []}
        for _ in range(rounds):
            for fast in (False, True):
                env.fast_step = fast
                env.reset_to_init(init)
                t = time.perf_counter()
                for a in actions:
                    env.step(a)
                runs["fast" if fast else "robosuite"].append((time.perf_counter() - t) / len(actions))
            runs["mj_step"].append(physics_only(env, init, actions, split=False))
            runs["split"].append(physics_only(env, init, actions, split=True))
    return {k: float(np.median(v)) * 1e3 for k, v in runs.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--suite", default="libero_spatial")
    ap.add_argument("--task-index", type=int, default=0)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--init", type=int, default=0)
    args = ap.parse_args()

    env = SimEnv(tasks([args.suite])[args.task_index])
    actions = recorded_expert(env, args.init, args.steps)
    labels = ["fast step"] + [f"+ {p.replace('_', ' ')}" for p in PIECES] + ["robosuite env.step"]
    times: dict[str, list[float]] = {k: [] for k in labels}
    finals: dict[str, np.ndarray] = {}

    def play(label: str, level: int | None) -> None:
        env.fast_step = level is not None
        if level is not None:
            env._stepper = AddBackStepper(env.env, level)
        env.reset_to_init(args.init)
        t = time.perf_counter()
        for a in actions:
            env.step(a)
        times[label].append((time.perf_counter() - t) / len(actions))
        finals[label] = env.get_state()

    for _ in range(args.rounds):
        for level, label in enumerate(labels):
            play(label, level if label != "robosuite env.step" else None)
    floor_step = [physics_only(env, args.init, actions, split=False) for _ in range(args.rounds)]
    floor_split = [physics_only(env, args.init, actions, split=True) for _ in range(args.rounds)]
    env.close()

    ref = finals["robosuite env.step"]
    print(f"{env.task.task_id}, {len(actions)} control steps of the scripted expert with noise, "
          f"median of {args.rounds} rounds, ms per control step")
    prev = None
    for label in labels:
        ms = float(np.median(times[label])) * 1e3
        same = "same final state" if np.array_equal(finals[label], ref) else "STATE DIFFERS"
        delta = "" if prev is None or label == "robosuite env.step" else f"  (this piece: {ms - prev:+6.2f} ms)"
        print(f"  {label:<26} {ms:7.2f}{delta}  {same}")
        prev = ms
    fast, rs = np.median(times["fast step"]) * 1e3, np.median(times["robosuite env.step"]) * 1e3
    f25, f12 = np.median(floor_step) * 1e3, np.median(floor_split) * 1e3
    print(f"  physics inside: 25 x mj_step {f25:.2f} ms; 25 x (mj_step1 + mj_step2) {f12:.2f} ms")
    print(f"  control step: robosuite {rs:.2f} ms = {rs / f25:.2f}x its 25 mj_step; fast {fast:.2f} ms = "
          f"{fast / f25:.2f}x; speed-up {rs / fast:.2f}x")


if __name__ == "__main__":
    main()
