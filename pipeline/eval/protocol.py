"""One evaluation trial: restore, perturb, initialize the gripper, roll out, record.

Input: a built `SimEnv` for the scene's task (from the scene's own BDDL), a `Policy`, and
a `Trial` (what to run). Output: an `EvalEpisode` row with the trajectory.

Protocol (scene mode): restore the scene's state -> shift every free-joint object by the
seeded horizontal offset (`perturb`) -> initialize the gripper open/closed with zero-delta
arm actions and re-anchor the controller (`gripper_init`) -> roll the policy out closed
loop (`pipeline.rollout.run_episode`) for at most `horizon` steps; success = the goal holds
after some step before the horizon. RD mode starts from a state of the original failed
rollout instead, unperturbed, with the gripper command that was in force there. Official
mode starts from LIBERO's official init state number `trial` of the task (as LIBERO's own
evaluation), unperturbed, gripper open: standard LIBERO success beside RSR.

Invariants: a trial is a deterministic function of (seed, scene, trial, start step,
gripper, chunk size, policy): offsets and the policy's seed derive from
(seed, scene_id, trial[, start step]) only, and env reuse is bit-identical (`SimEnv`).
"""

from __future__ import annotations

import hashlib
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.errors import EpisodeError
from pipeline.eval.gripper_init import init_gripper
from pipeline.eval.perturb import perturb
from pipeline.eval.records import EvalEpisode, unit_id
from pipeline.eval.scenes import Scene
from pipeline.rollout import StepInfo, run_episode


@dataclass(frozen=True)
class Trial:
    scene: Scene
    policy: str
    policy_kind: str
    gripper: str  # open | closed
    trial: int
    seed: int  # run seed
    chunk_size: int
    horizon: int
    max_offset_m: float
    gripper_settle_steps: int
    temporal_context: str = "none"  # none | initial_frame | history
    mode: str = "scene"  # scene | rd | official
    rd_phase: str | None = None
    rd_start_step: int | None = None
    rd_folder: Path | None = None  # stage-1 episode folder holding states.npy

    @property
    def unit_id(self) -> str:
        return unit_id(self.policy, self.chunk_size, self.mode, self.scene.scene_id, self.gripper, self.trial,
                       self.rd_start_step)


def policy_seed(seed: int, scene_id: str, trial: int, start_step: int | None = None) -> int:
    """The seed handed to `policy.reset`: from the trial's identity, never the policy's."""
    digest = hashlib.sha256(f"{seed}/{scene_id}/{trial}/{start_step}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def source_init_state(scene: Scene) -> int | None:
    if scene.init_state is not None:
        return scene.init_state
    m = re.search(r"-i(\d+)-", scene.episode_id)  # stage-1 ids: <policy>-i<NN>-s<seed>
    return int(m.group(1)) if m else None


HISTORY_FRAMES = 8  # the reference's history variant: the 8 frames before the failure


def temporal_context(env, policy, trial: Trial) -> dict:
    """What an accepting policy gets in `Observation.context` (call before restoring)."""
    if trial.temporal_context == "none" or not getattr(policy, "accepts_context", False):
        return {}
    if trial.temporal_context == "history":
        if trial.mode != "scene" or not trial.scene.history_paths:
            return {}
        hist = {}
        for p in trial.scene.history_paths:
            if p.suffix == ".npz":
                with np.load(p) as z:
                    hist.update({k: z[k] for k in z.files})
        ctx = {"kind": "history", "history": hist, "history_paths": [str(p) for p in trial.scene.history_paths]}
        cams = list(getattr(policy, "cameras", ()))
        if cams and "sim_states" in hist and len(hist["sim_states"]):
            # image policies see the history as frames: its last HISTORY_FRAMES logged states,
            # rendered like the current frames (the released history holds states, not pixels)
            ctx["history_images"] = env.render_states(hist["sim_states"][-HISTORY_FRAMES:], cams, policy.image_size)
        return ctx
    index = official_index(env, trial) if trial.mode == "official" else source_init_state(trial.scene)
    if index is None:
        return {}
    state = env.task.init_states()[index]
    env.reset_to(state)
    images = {cam: env.render(cam, policy.image_size) for cam in policy.cameras}
    return {"kind": "initial_frame", "initial_state": state, "initial_images": images}


def official_index(env, trial: Trial) -> int:
    return trial.trial % len(env.task.init_states())


def start_state(trial: Trial, env=None) -> np.ndarray:
    if trial.mode == "official":
        return env.task.init_states()[official_index(env, trial)]
    if trial.mode == "rd":
        from pipeline.eval.rd import load_start_state

        return load_start_state(trial.rd_folder, trial.rd_start_step)
    try:
        return np.load(trial.scene.state_path)
    except (OSError, ValueError) as e:
        raise EpisodeError("unreadable_state", f"{trial.scene.state_path}: {e}") from None


def run_trial(env, policy, trial: Trial) -> EvalEpisode:
    t0 = time.perf_counter()
    scene = trial.scene
    context = temporal_context(env, policy, trial)
    state = start_state(trial, env)
    try:
        env.reset_to(state)
    except ValueError as e:
        where = {"scene": trial.scene.state_path, "rd": trial.rd_folder, "official": env.task.init_states_path}
        raise EpisodeError("state_mismatch", f"{where[trial.mode]}: {e}") from None
    offsets = {}
    if trial.mode == "scene":
        offsets = perturb(env, trial.seed, scene.scene_id, trial.trial, trial.max_offset_m)
    g = init_gripper(env, trial.gripper, trial.gripper_settle_steps)
    pseed = policy_seed(trial.seed, scene.scene_id, trial.trial, trial.rd_start_step)
    policy.reset(env.task, pseed)
    actions: list[list[float]] = []
    eef: list[list[float]] = [env.eef_pose()[0].tolist()]

    def on_step(info: StepInfo) -> None:
        actions.append(info.action.tolist())
        eef.append(env.eef_pose()[0].tolist())

    res = run_episode(env, policy, trial.horizon, trial.chunk_size, stop_on_success=True, on_step=on_step,
                      context=context)
    official = trial.mode == "official"  # no failure, no scene: the task from its init state
    return EvalEpisode(
        mode=trial.mode, scene_id=scene.scene_id, suite=scene.suite, task=scene.task,
        instruction=scene.instruction or env.task.instruction,
        episode_id=f"official-i{official_index(env, trial):02d}" if official else scene.episode_id,
        scene_step=0 if official else scene.step, level=None if official else scene.level,
        category=None if official else scene.category, policy=trial.policy,
        policy_kind=trial.policy_kind, gripper=trial.gripper, trial=trial.trial, seed=trial.seed,
        policy_seed=pseed, chunk_size=trial.chunk_size, horizon=trial.horizon,
        temporal_context=context.get("kind", "none"), offsets=offsets,
        gripper_settle_steps=trial.gripper_settle_steps, init_eef_drift_m=g.eef_drift_m,
        init_gripper_opening=g.opening, rd_phase=trial.rd_phase, rd_start_step=trial.rd_start_step,
        steps=res.steps, success=res.success, first_success_step=res.first_success_step,
        wall_time_s=time.perf_counter() - t0, actions=actions, eef_pos=eef,
    )
