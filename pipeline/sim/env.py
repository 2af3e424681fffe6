"""One LIBERO task environment: the only place that talks to LIBERO, robosuite and MuJoCo.

Building an environment is slow (about 4-8 s: XML assembly and model compilation); an
episode start is cheap. So build one `SimEnv` per task and reuse it across that task's
episodes: `reset_to(state)` is `pipeline.sim.restore.restore` (the one restore, which the
dataset card prints): LIBERO's seeded reset and `set_init_state`, exactly as LIBERO's
evaluation does, plus what the flattened MuJoCo state does not hold (controller anchor,
gripper command ramp, solver warm start), so an episode is bit-identical whether it runs in
a fresh or a reused environment, here or in plain LIBERO.

Quirks kept here and nowhere else:
- robosuite images are upside down; `render` uses `mujoco.Renderer`, which is not.
- the Panda gripper ramps its command (`current_action`) across steps: it is not part of
  the MuJoCo state, so a restored closed gripper needs some close commands to stay closed.
- robosuite's own horizon/done handling is disabled (`ignore_done`); runners own horizons.
- `step` runs `FastStepper` (fast_step.py): robosuite's control step without the work whose
  results nobody reads, bit-identical states and goal checks. `SimEnv(task, fast_step=False)`
  steps through robosuite's own `env.step` (identity tests, benchmarks).
- LIBERO re-samples fixture poses (cabinets, stoves, racks; about +-1 cm) at every reset
  from the global `np.random`, and fixture poses are NOT part of the flattened state. So
  every reset here seeds that sampler with `FIXTURE_SEED` (and restores the caller's global
  RNG state afterwards): fixtures sit at one pose per task in every episode, every process
  and every restored scene. Plain LIBERO gets the same layout with `np.random.seed(0)`
  right before `env.reset()`.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass

import numpy as np

from pipeline.sim.facts import JointFrame, JointKind, Region
from pipeline.sim.fast_step import FastStepper
from pipeline.sim.libero_setup import ensure_libero_ready
from pipeline.sim.registry import TaskSpec
from pipeline.sim.restore import restore
from pipeline.sim.render import CAMERAS, FrameRenderer

ACTION_DIM = 7  # delta position (3), delta axis-angle (3), gripper (-1 open, +1 close)
CONTROL_HZ = 20
FIXTURE_SEED = 0  # seeds LIBERO's fixture placement at every reset (see the module docstring)


@dataclass(frozen=True)
class Contact:
    a: str  # owner of the first geom: an object/fixture name or "robot"
    b: str


def _quiet():
    # LIBERO and robosuite print banners on import and build; keep the terminal for progress
    return contextlib.redirect_stdout(io.StringIO())


class SimEnv:
    """A built LIBERO environment for one task. Not thread-safe; one per worker process."""

    def __init__(self, task: TaskSpec, control_hz: int = CONTROL_HZ, fast_step: bool = True):
        ensure_libero_ready()
        with _quiet():
            from libero.libero.envs.env_wrapper import ControlEnv

            self._wrapper = ControlEnv(
                bddl_file_name=str(task.bddl_path),
                has_renderer=False,
                has_offscreen_renderer=False,  # we render through mujoco.Renderer on demand
                use_camera_obs=False,
                control_freq=control_hz,
                horizon=10**9,
                ignore_done=True,
                hard_reset=False,  # soft resets keep the compiled model: cheap episode starts
            )
            self._seeded_reset()
        self.task = task
        self.env = self._wrapper.env  # the robosuite/LIBERO domain object
        self._stepper = FastStepper(self.env)
        self.fast_step = fast_step  # False: robosuite's own env.step (same states, slower)
        self._renderers: dict[tuple[int, str], FrameRenderer] = {}
        self._owner = self._body_owners()

    # ---- episode lifecycle -------------------------------------------------------------
    @property
    def state_dim(self) -> int:
        m = self.env.sim.model
        return 1 + m.nq + m.nv

    def reset_to(self, state: np.ndarray, hold_grasp: bool = False) -> None:
        """Start an episode from a flattened MuJoCo state (an init state or a saved scene)
        with `pipeline.sim.restore.restore`, the one restore (the dataset card prints it);
        the caller's global RNG is left as it was. `hold_grasp`: set the gripper's command
        ramp from the finger opening (a restored scene), else zero (an episode start)."""
        state = np.asarray(state, dtype=np.float64)
        if state.shape != (self.state_dim,):
            raise ValueError(
                f"state has shape {state.shape}, but task {self.task.task_id} needs ({self.state_dim},)"
            )
        saved = np.random.get_state()
        try:
            with _quiet():
                restore(self._wrapper, state, hold_grasp=hold_grasp)
        finally:
            np.random.set_state(saved)

    @property
    def libero(self):
        """The LIBERO `ControlEnv` itself: `step` here is robosuite's own `env.step`."""
        return self._wrapper

    def _seeded_reset(self) -> None:
        """LIBERO's reset with its fixture placement drawn from a fixed seed."""
        saved = np.random.get_state()
        np.random.seed(FIXTURE_SEED)
        try:
            self._wrapper.reset()
        finally:
            np.random.set_state(saved)

    def fixture_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """World pose of every fixture: not in the flattened state, fixed by the seeded reset."""
        return {n: self.object_pose(n) for n in self.fixture_names}

    def reset_to_init(self, index: int) -> None:
        self.reset_to(self.task.init_states()[index])

    def get_state(self) -> np.ndarray:
        """Flattened MuJoCo state (time, qpos, qvel), as LIBERO's `get_sim_state`."""
        return np.array(self.env.sim.get_state().flatten(), dtype=np.float64)

    def set_state(self, state: np.ndarray) -> None:
        """Restore a flattened state mid-episode (no reset), as LIBERO's `set_init_state`."""
        self._wrapper.set_init_state(np.asarray(state, dtype=np.float64))

    def step(self, action: np.ndarray) -> bool:
        """One 20 Hz control step; returns whether the task goal holds afterwards."""
        action = np.asarray(action, dtype=np.float64)
        if action.shape != (ACTION_DIM,):
            raise ValueError(f"action must have shape ({ACTION_DIM},), got {action.shape}")
        if self.fast_step:
            return self._stepper.step(action)
        _, _, done, _ = self.env.step(action)
        return bool(done)

    def settle(self, steps: int, gripper: float = -1.0) -> None:
        """Zero-delta arm actions for `steps` steps, holding the gripper command."""
        a = np.zeros(ACTION_DIM)
        a[-1] = gripper
        for _ in range(steps):
            self.step(a)

    def reanchor_controller(self) -> None:
        """Make the arm controller's goal the current end-effector pose.

        The controller caches the pose it last read (`update` is lazy), and after a state
        restore that cache still holds the pre-restore pose: anchoring to it makes the arm
        swing back toward it (measured 13 mm on libero_spatial). Force a fresh read first.
        """
        controller = self.env.robots[0].controller
        controller.update(force=True)
        controller.reset_goal()

    def hold_gripper(self, closed: bool) -> None:
        """Set the gripper's command ramp to fully closed/open without stepping, so a restored
        scene keeps its grasp: the ramp is not in the MuJoCo state (see module docstring)."""
        gripper = self.env.robots[0].gripper
        gripper.current_action = np.array([-1.0, 1.0]) * (1.0 if closed else -1.0)

    # ---- goal ---------------------------------------------------------------------------
    @property
    def goal(self) -> list[tuple[str, ...]]:
        """The goal's conjuncts, e.g. [('on', 'akita_black_bowl_1', 'plate_1')]."""
        return [tuple(s) for s in self.env.parsed_problem["goal_state"]]

    def goal_satisfied(self) -> bool:
        return bool(self.env._check_success())

    def goal_conjuncts(self) -> list[tuple[tuple[str, ...], bool]]:
        return [(c, bool(self.env._eval_predicate(list(c)))) for c in self.goal]

    # ---- scene contents -----------------------------------------------------------------
    @property
    def object_names(self) -> list[str]:
        """Movable objects (with a free joint)."""
        return list(self.env.objects_dict.keys())

    @property
    def fixture_names(self) -> list[str]:
        return list(self.env.fixtures_dict.keys())

    def object_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) and quaternion (w, x, y, z) of an object's or fixture's body."""
        bid = self.env.obj_body_id[name]
        d = self.env.sim.data
        return np.array(d.body_xpos[bid]), np.array(d.body_xquat[bid])

    def object_frame(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World position (3,) and rotation matrix (3, 3; columns: the body's axes) of an
        object's or fixture's body."""
        bid = self.env.obj_body_id[name]
        d = self.env.sim.data
        return np.array(d.body_xpos[bid]), np.array(d.body_xmat[bid]).reshape(3, 3)

    def object_com(self, name: str) -> np.ndarray:
        """World centre of mass of an object (its body and the bodies below it)."""
        return np.array(self.env.sim.data.subtree_com[self.env.obj_body_id[name]])

    def object_poses(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {n: self.object_pose(n) for n in self.object_names}

    def free_joints(self) -> dict[str, int]:
        """Object name -> qpos address of its free joint (7 numbers: xyz + wxyz)."""
        m = self.env.sim.model
        out = {}
        for name, obj in self.env.objects_dict.items():
            jname = obj.joints[-1] if obj.joints else None
            if jname is None:
                continue
            jid = m.joint_name2id(jname)
            if m.jnt_type[jid] == 0:  # mjJNT_FREE
                out[name] = int(m.jnt_qposadr[jid])
        return out

    def site_position(self, name: str) -> np.ndarray:
        return np.array(self.env.sim.data.site_xpos[self.env.sim.model.site_name2id(name)])

    def joint_position(self, name: str) -> float:
        m = self.env.sim.model
        return float(self.env.sim.data.qpos[m.jnt_qposadr[m.joint_name2id(name)]])

    def object_state(self, name: str):
        """LIBERO's state object (what its predicates use) for an object, fixture or region."""
        return self.env.object_states_dict[name]

    # ---- geometry (for the scripted expert's planner) -----------------------------------
    def _geom_boxes(self, geom_ids: list[int]) -> np.ndarray:
        """(k, 2, 3) world-axis-aligned [lo, hi] boxes of the given geoms."""
        m = self.env.sim.model._model
        d = self.env.sim.data._data
        out = np.empty((len(geom_ids), 2, 3))
        for i, g in enumerate(geom_ids):
            rot = d.geom_xmat[g].reshape(3, 3)
            centre = d.geom_xpos[g] + rot @ m.geom_aabb[g, :3]
            half = np.abs(rot) @ m.geom_aabb[g, 3:]
            out[i] = centre - half, centre + half
        return out

    def _collision_geoms(self, bodies: set[int]) -> list[int]:
        m = self.env.sim.model._model
        return [
            g
            for g in range(m.ngeom)
            if int(m.geom_bodyid[g]) in bodies and (m.geom_contype[g] or m.geom_conaffinity[g])
        ]

    def object_boxes(self, name: str) -> np.ndarray:
        """World boxes (k, 2, 3) of the collision geoms of an object or fixture (all its bodies)."""
        bodies = {b for b in range(len(self._owner)) if self._owner[b] == name}
        if not bodies:
            raise KeyError(f"no object or fixture {name!r} in task {self.task.task_id}")
        return self._geom_boxes(self._collision_geoms(bodies))

    def body_geom_frames(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The collision geoms of an object's own body (not the bodies below it): world
        positions (k, 3), rotations (k, 3, 3) and local bounding boxes (k, 6: centre, half)."""
        m = self.env.sim.model._model
        d = self.env.sim.data._data
        bid = self.env.obj_body_id[name]
        geoms = self._collision_geoms({bid})
        return (np.array([d.geom_xpos[g] for g in geoms]).reshape(-1, 3),
                np.array([d.geom_xmat[g].reshape(3, 3) for g in geoms]).reshape(-1, 3, 3),
                np.array([m.geom_aabb[g] for g in geoms]).reshape(-1, 6))

    def object_corners(self, name: str) -> np.ndarray:
        """(k*8, 3) world corners of the oriented boxes bounding an object's collision geoms."""
        m = self.env.sim.model._model
        d = self.env.sim.data._data
        bodies = {b for b in range(len(self._owner)) if self._owner[b] == name}
        signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], dtype=float)
        out = []
        for g in self._collision_geoms(bodies):
            rot = d.geom_xmat[g].reshape(3, 3)
            local = m.geom_aabb[g, :3] + signs * m.geom_aabb[g, 3:]
            out.append(d.geom_xpos[g] + local @ rot.T)
        return np.concatenate(out) if out else np.empty((0, 3))

    def ray_down(self, xy: np.ndarray, z_from: float, z_to: float, ignore: str | None = None) -> float | None:
        """Height of the first non-robot collision surface straight below (xy, z_from), or
        None when nothing lies above `z_to`; `ignore` names an object to see through too."""
        import mujoco

        m = self.env.sim.model._model
        d = self.env.sim.data._data
        geom = np.array([-1], dtype=np.int32)
        groups = np.array([1, 0, 0, 0, 0, 0], dtype=np.uint8)  # LIBERO's collision geoms: group 0
        z = float(z_from)
        while z > z_to:
            dist = mujoco.mj_ray(m, d, np.array([xy[0], xy[1], z]), np.array([0.0, 0.0, -1.0]), groups, 1, -1, geom)
            if dist < 0 or z - dist < z_to:
                return None
            if self._owner[m.geom_bodyid[geom[0]]] not in ("robot", ignore):
                return z - dist
            z = z - dist - 1e-4  # passed through the robot's own geometry: look further down
        return None

    def object_aabb(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned bounding box (lo, hi) of an object's collision geoms."""
        boxes = self.object_boxes(name)
        return boxes[:, 0].min(axis=0), boxes[:, 1].max(axis=0)

    def _joint_part_geoms(self, joint: str) -> list[int]:
        """Collision geoms moved by a joint: its body and the bodies below it."""
        m = self.env.sim.model._model
        root = int(m.jnt_bodyid[m.joint(joint).id])
        bodies = {root}
        for b in range(root + 1, m.nbody):
            if int(m.body_parentid[b]) in bodies:
                bodies.add(b)
        return self._collision_geoms(bodies)

    def joint_part_boxes(self, joint: str) -> np.ndarray:
        """World boxes of the collision geoms moved by a joint (its body and descendants)."""
        return self._geom_boxes(self._joint_part_geoms(joint))

    def joint_part_axes(self, joint: str) -> np.ndarray:
        """(k, 3, 3) world rotations of the same geoms as `joint_part_boxes` (columns: the
        geom's local axes), so a planner can tell a bar's long side at any joint angle."""
        d = self.env.sim.data._data
        geoms = self._joint_part_geoms(joint)
        return np.array([d.geom_xmat[g].reshape(3, 3) for g in geoms]).reshape(len(geoms), 3, 3)

    def joint_part_half_sizes(self, joint: str) -> np.ndarray:
        """(k, 3) local half sizes (of the bounding box) of the same geoms."""
        m = self.env.sim.model._model
        return np.array([m.geom_aabb[g, 3:] for g in self._joint_part_geoms(joint)]).reshape(-1, 3)

    def joint_frame(self, joint: str) -> JointFrame:
        """A joint's world anchor and axis, its position, range and kind (slide or hinge)."""
        m = self.env.sim.model._model
        d = self.env.sim.data._data
        j = m.joint(joint).id
        return JointFrame(
            anchor=np.array(d.xanchor[j]),
            axis=np.array(d.xaxis[j]),
            qpos=float(d.qpos[m.jnt_qposadr[j]]),
            range=np.array(m.jnt_range[j]),
            kind={2: JointKind.SLIDE, 3: JointKind.HINGE}.get(int(m.jnt_type[j]), JointKind.OTHER),
        )

    def region(self, name: str) -> Region:
        """A region site: world position, rotation, half size, parent name and its joints."""
        site = self.env.object_sites_dict[name]
        sid = self.env.sim.model.site_name2id(name)
        d = self.env.sim.data
        return Region(
            pos=np.array(d.site_xpos[sid]),
            mat=np.array(d.site_xmat[sid]).reshape(3, 3),
            size=np.array(site.size, dtype=float),
            parent=site.parent_name,
            joints=tuple(site.joints or ()),
        )

    @property
    def region_names(self) -> list[str]:
        """Every region site of the task (drawer insides, cook regions, ...)."""
        return list(self.env.object_sites_dict)

    def is_region(self, name: str) -> bool:
        return name in self.env.object_sites_dict

    def fixture_joints(self, name: str) -> list[str]:
        """Names of the (non-free) joints of an object or fixture, e.g. a stove's knob."""
        return list(self.env.get_object(name).joints or [])

    # ---- robot --------------------------------------------------------------------------
    def eef_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """End-effector (grip site) position (3,) and rotation matrix (3, 3)."""
        robot = self.env.robots[0]
        d = self.env.sim.data
        return np.array(d.site_xpos[robot.eef_site_id]), np.array(d.site_xmat[robot.eef_site_id]).reshape(3, 3)

    def robot_base(self) -> np.ndarray:
        """World position (3,) of the robot's base body (planners measure reach from it)."""
        sim = self.env.sim
        return np.array(sim.data.body_xpos[sim.model.body_name2id("robot0_base")])

    def _arm_joint_ids(self) -> list[int]:
        """MuJoCo ids of the arm's seven joints, base to wrist."""
        m = self.env.sim.model
        return [m.joint_name2id(f"robot0_joint{i}") for i in range(1, 8)]

    def arm_joints(self) -> tuple[np.ndarray, np.ndarray]:
        """The arm's joint positions (7,) and limits (7, 2), base to wrist."""
        sim = self.env.sim
        m = sim.model
        ids = self._arm_joint_ids()
        return np.array([sim.data.qpos[m.jnt_qposadr[j]] for j in ids]), np.array([m.jnt_range[j] for j in ids])

    def arm_home(self) -> np.ndarray:
        """The arm's home joints (7,): the start pose, which the OSC controller's null space
        pulls the arm toward (robosuite's `initial_joint`)."""
        return np.array(self.env.robots[0].controller.initial_joint, dtype=float)

    def eef_pose_at(self, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grip-site position (3,) and rotation (3, 3) with the arm at `joints` (7,) and the
        rest of the scene as it is now: forward kinematics on a scratch copy (the live state
        is not touched)."""
        import mujoco

        sim = self.env.sim
        m = sim.model
        data = mujoco.MjData(m._model)
        data.qpos[:] = sim.data._data.qpos
        ids = self._arm_joint_ids()
        data.qpos[[m.jnt_qposadr[j] for j in ids]] = joints
        mujoco.mj_kinematics(m._model, data)
        site = self.env.robots[0].eef_site_id
        return np.array(data.site_xpos[site]), np.array(data.site_xmat[site]).reshape(3, 3)

    def ik_residual(self, pos: np.ndarray, rot: np.ndarray, iters: int = 150) -> tuple[float, float]:
        """How near the arm gets to the grip-site pose (`pos`, rotation `rot`) from its
        present joints: (metres, radians) left (`ik_reach`)."""
        _, off_m, off_rad = self.ik_reach(pos, rot, iters=iters)
        return off_m, off_rad

    def ik_reach(self, pos: np.ndarray, rot: np.ndarray, start: np.ndarray | None = None,
                 iters: int = 150) -> tuple[np.ndarray, float, float]:
        """(joints (7,), metres, radians left) where the arm ends going to the grip-site pose
        (`pos`, rotation `rot`) by damped least squares from `start` (its present joints by
        default), each step clamped to the joint limits, on a scratch copy (the live state
        is not touched). Like the operational-space controller it follows the local
        gradient, so a pose the wrist reaches only past a joint limit the other way round
        stays off; chained through the joints it returns, it follows a sequence of moves."""
        import mujoco

        sim = self.env.sim
        m = sim.model
        data = mujoco.MjData(m._model)
        data.qpos[:] = sim.data._data.qpos
        ids = self._arm_joint_ids()
        qadr = [m.jnt_qposadr[j] for j in ids]
        dofs = [m.jnt_dofadr[j] for j in ids]
        lo, hi = np.array([m.jnt_range[j] for j in ids]).T
        if start is not None:
            data.qpos[qadr] = start
        site = self.env.robots[0].eef_site_id
        home = self.arm_home()
        jp, jr = np.zeros((3, m._model.nv)), np.zeros((3, m._model.nv))
        want, have, local = np.zeros(4), np.zeros(4), np.zeros(3)
        mujoco.mju_mat2Quat(want, np.asarray(rot, dtype=float).reshape(9))
        err = np.zeros(6)
        for _ in range(iters):
            mujoco.mj_kinematics(m._model, data)
            mujoco.mj_comPos(m._model, data)
            now = data.site_xmat[site].reshape(3, 3)
            # the rotation still to go as a world rotation vector (MuJoCo's quaternion
            # difference is in the present frame, and holds up to a half turn)
            mujoco.mju_mat2Quat(have, data.site_xmat[site])
            mujoco.mju_subQuat(local, want, have)
            err = np.concatenate([np.asarray(pos) - data.site_xpos[site], now @ local])
            if np.linalg.norm(err[:3]) < 1e-3 and np.linalg.norm(err[3:]) < 1e-3:
                break
            mujoco.mj_jacSite(m._model, data, jp, jr, site)
            jac = np.vstack([jp[:, dofs], jr[:, dofs]])
            pinv = jac.T @ np.linalg.inv(jac @ jac.T + 1e-2 * np.eye(6))
            # the controller's null space pulls toward the home joints as it goes
            dq = pinv @ err + (np.eye(7) - pinv @ jac) @ (0.1 * (home - data.qpos[qadr]))
            dq *= min(1.0, 0.2 / max(float(np.abs(dq).max()), 1e-9))  # small steps: a path, not a jump
            data.qpos[qadr] = np.clip(data.qpos[qadr] + dq, lo, hi)
        return data.qpos[qadr].copy(), float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))

    def eef_hand_quat(self) -> np.ndarray:
        """robosuite's `robot0_eef_quat` (x, y, z, w): MuJoCo's quaternion of the hand body,
        with MuJoCo's sign, which VLA policies trained on LIBERO data expect in their state
        (the grip site's rotation differs by a fixed 90 deg turn and has no sign)."""
        robot = self.env.robots[0]
        w, x, y, z = self.env.sim.data.get_body_xquat(robot.robot_model.eef_name)
        return np.array([x, y, z, w])

    def robot_observables(self) -> dict[str, np.ndarray]:
        """robosuite's proprioceptive observables of robot0, as its observation dict names them
        (what LeRobot's LIBERO env reads: `lerobot/envs/libero.py:_format_raw_obs`), read from
        the current state, plus the controller's end-effector rotation (`ee_ori_mat`)."""
        robot = self.env.robots[0]
        d = self.env.sim.data
        return {
            "robot0_eef_pos": np.array(d.site_xpos[robot.eef_site_id]),
            "robot0_eef_quat": self.eef_hand_quat(),
            "robot0_gripper_qpos": np.array(d.qpos[robot._ref_gripper_joint_pos_indexes]),
            "robot0_gripper_qvel": np.array(d.qvel[robot._ref_gripper_joint_vel_indexes]),
            "robot0_joint_pos": np.array(d.qpos[robot._ref_joint_pos_indexes]),
            "robot0_joint_vel": np.array(d.qvel[robot._ref_joint_vel_indexes]),
            "ee_ori_mat": np.array(robot.controller.ee_ori_mat),
        }

    def gripper_qpos(self) -> np.ndarray:
        robot = self.env.robots[0]
        return np.array(self.env.sim.data.qpos[robot._ref_gripper_joint_pos_indexes])

    def gripper_opening(self) -> float:
        """Distance between the two fingers' joints, metres (about 0.08 open, ~0 closed)."""
        q = self.gripper_qpos()
        return float(q[0] - q[1])

    # ---- contacts -----------------------------------------------------------------------
    def _body_owners(self) -> np.ndarray:
        """For each body id: the object/fixture name it belongs to, 'robot', or ''."""
        m = self.env.sim.model
        roots = {}
        for name in list(self.env.objects_dict) + list(self.env.fixtures_dict):
            roots[self.env.obj_body_id[name]] = name
        owners = np.empty(m.nbody, dtype=object)
        for b in range(m.nbody):
            name, cur = "", b
            while cur > 0:
                if cur in roots:
                    name = roots[cur]
                    break
                bname = m.body_id2name(cur) or ""
                if bname.startswith(("robot0_", "gripper0_")):
                    name = "robot"
                    break
                if int(m.body_parentid[cur]) == 0 and ("table" in bname or "floor" in bname):
                    # the arena's support surfaces are not BDDL objects; name them so contacts
                    # with them (an object resting, a fall) are visible
                    name = "table" if "table" in bname else "floor"
                    break
                cur = int(m.body_parentid[cur])
            owners[b] = name
        return owners

    def finger_contacts(self) -> tuple[set[str], set[str]]:
        """Owners (objects, fixtures, 'table') touched by the left and by the right finger."""
        m, d = self.env.sim.model, self.env.sim.data
        if not hasattr(self, "_finger_geoms"):
            g = self.env.robots[0].gripper.important_geoms
            self._finger_geoms = tuple({m.geom_name2id(n) for n in g[k]} for k in ("left_finger", "right_finger"))
        left, right = set(), set()
        for i in range(d.ncon):
            c = d.contact[i]
            for mine, other in ((c.geom1, c.geom2), (c.geom2, c.geom1)):
                owner = self._owner[m.geom_bodyid[other]]
                if owner and owner != "robot":
                    if mine in self._finger_geoms[0]:
                        left.add(owner)
                    elif mine in self._finger_geoms[1]:
                        right.add(owner)
        return left, right

    def object_speeds(self) -> dict[str, float]:
        """Linear speed (m/s) of each movable object, from its free joint's qvel."""
        m, d = self.env.sim.model, self.env.sim.data
        out = {}
        for name, obj in self.env.objects_dict.items():
            if not obj.joints:
                continue
            jid = m.joint_name2id(obj.joints[-1])
            if m.jnt_type[jid] == 0:  # mjJNT_FREE: first three dofs are the linear velocity
                a = int(m.jnt_dofadr[jid])
                out[name] = float(np.linalg.norm(d.qvel[a : a + 3]))
        return out

    def contacts(self) -> list[tuple[str, str]]:
        """Pairs of named things in contact now (robot, objects, fixtures, table), each pair
        sorted and the list sorted: a set of strings iterates in a per-process hash order,
        which made policies that scan contacts differ between runs of the same seed."""
        m, d = self.env.sim.model, self.env.sim.data
        pairs = set()
        for i in range(d.ncon):
            c = d.contact[i]
            a = self._owner[m.geom_bodyid[c.geom1]]
            b = self._owner[m.geom_bodyid[c.geom2]]
            if a and b and a != b:
                pairs.add(tuple(sorted((a, b))))
        return sorted(pairs)

    # ---- rendering ----------------------------------------------------------------------
    def render(self, camera: str = "agentview", size: int = 256, quality: str = "standard") -> np.ndarray:
        """HxWx3 uint8 frame of `camera`, right side up, for the current state. `quality`
        "fast" is for videos people and VLMs watch, never for policy inputs (see render.py)."""
        if camera not in CAMERAS:
            raise ValueError(f"unknown camera {camera!r}; choose from {CAMERAS}")
        r = self._renderers.get((size, quality))
        if r is None:
            r = self._renderers[(size, quality)] = FrameRenderer(self.env.sim.model._model, size, quality)
        return r.render(self.env.sim.data._data, camera)

    def render_states(self, states: np.ndarray, cameras: list[str], size: int,
                      quality: str = "standard") -> dict[str, np.ndarray]:
        """(k, S, S, 3) uint8 frames per camera of k logged states, in order (leaves the
        env at the last state)."""
        frames: dict[str, list[np.ndarray]] = {cam: [] for cam in cameras}
        for state in states:
            self.set_state(state)
            for cam in cameras:
                frames[cam].append(self.render(cam, size, quality))
        return {cam: np.asarray(f, dtype=np.uint8).reshape(len(states), size, size, 3) for cam, f in frames.items()}

    def project(self, camera: str, size: int, points: np.ndarray) -> np.ndarray:
        """Pixel (column, row) of world points in a `size`x`size` image of `camera`, row 0 at
        the top, as `render` draws them (pinhole model from MuJoCo's camera pose and fovy)."""
        m, d = self.env.sim.model, self.env.sim.data
        cid = m.camera_name2id(camera)
        pos = np.array(d.cam_xpos[cid])
        rot = np.array(d.cam_xmat[cid]).reshape(3, 3)  # columns: camera x, y, z in world
        f = 0.5 * size / np.tan(np.deg2rad(m.cam_fovy[cid]) / 2)
        local = (np.atleast_2d(points) - pos) @ rot  # MuJoCo cameras look along -z, y up
        col = size / 2 + f * local[:, 0] / -local[:, 2]
        row = size / 2 - f * local[:, 1] / -local[:, 2]
        return np.stack([col, row], axis=1)

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
        with _quiet():
            self._wrapper.close()

    def __enter__(self) -> SimEnv:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def parse_bddl(path) -> dict:
    """Parse a BDDL problem file with LIBERO's own parser; raise ValueError naming the file."""
    ensure_libero_ready()
    with _quiet():
        from libero.libero.envs.bddl_utils import robosuite_parse_problem

        try:
            parsed = robosuite_parse_problem(str(path))
        except Exception as e:  # LIBERO raises bare Exceptions and IndexErrors on bad syntax
            raise ValueError(f"{path}: LIBERO's BDDL parser failed: {type(e).__name__}: {e}") from None
    if not isinstance(parsed, dict):
        raise ValueError(f"{path}: not a BDDL problem (no top-level `(define ...)`)")
    return parsed


def build_env(task: TaskSpec) -> SimEnv:
    """Build an environment for `task` (seconds). Reuse it for all of the task's episodes."""
    return SimEnv(task)
