"""The scripted expert as a `Policy`: privileged state in, (N, 7) action chunks out.

Per episode (`reset`) it seeds its noise from (seed, task id); on the first `act` it
plans from the live scene (`obs.sim`), so it copes with any start state. Each `act`
first credits the steps the runner actually executed of the previous chunk to the
primitive that produced them (the runner may execute fewer than returned), then asks the
plan for the next unfinished primitive and returns its actions (at most `chunk_len`;
fewer when a primitive ends, so the next decision sees live state).
It also keeps the generator's own record (`truth.TruthLog`): the runner reports each
executed step through `on_step`, and `truth_table()` gives the episode's attempts.
"""

from __future__ import annotations

import numpy as np

from pipeline.config import ScriptedPolicyConfig
from pipeline.policies.base import Observation
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.noise import Noise, episode_rng
from pipeline.policies.scripted.planner import plan_episode
from pipeline.policies.scripted.primitives import Primitive, emit
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.truth import TruthLog
from pipeline.sim import TaskSpec


class ScriptedPolicy:
    cameras: tuple[str, ...] = ()

    def __init__(self, cfg: ScriptedPolicyConfig, name: str | None = None):
        self.cfg = cfg
        self.name = name or "scripted"
        self.image_size = 224
        self._task_id = ""
        self._seed = 0
        self._plan: Plan | None = None
        self._ctx: Ctx | None = None
        self._prim: Primitive | None = None
        self._last: tuple[Primitive, int, int] | None = None

    def reset(self, task: TaskSpec, seed: int) -> None:
        self._task_id = task.task_id
        self._seed = int(seed)
        self._plan = None
        self._ctx = None
        self._prim = None
        self._last = None

    def act(self, obs: Observation) -> np.ndarray:
        env = obs.sim
        if env is None:
            raise ValueError(f"policy {self.name}: the scripted expert needs privileged state (obs.sim)")
        if self._plan is None:
            self._ctx, self._plan = self._start(env)
        if self._last is not None:
            prim, n, step0 = self._last
            prim.steps += max(0, min(obs.step - step0, n))
        eef, rot = env.eef_pose()
        self._ctx.truth.step = obs.step  # skills resumed now act (and are recorded) at this step
        while self._prim is None or self._prim.done(eef, rot):
            self._prim = next(self._plan)
            self._ctx.truth.mark(self._prim.label)
        chunk = emit(self._prim, eef, rot, self.cfg.chunk_len, self._ctx.yaw_hold, self._ctx.approach_hold)
        chunk = self._ctx.noise.actions(chunk)
        self._last = (self._prim, len(chunk), obs.step)
        return chunk

    def _start(self, env) -> tuple[Ctx, Plan]:
        """The episode's context and plan, made on the first `act` from the live scene."""
        levels = self.cfg.noise_for(env.task.suite)
        noise = Noise(levels, episode_rng(self._seed, self._task_id or env.task.task_id))
        scene = Scene(env)
        truth = TruthLog(scene, levels.action_noise, noise.speed)
        ctx = Ctx(scene=scene, noise=noise, max_attempts=self.cfg.max_attempts, truth=truth)
        return ctx, plan_episode(ctx)

    @property
    def phase(self) -> str:
        """Label of the primitive being executed (for debugging and tests)."""
        return self._prim.label if self._prim is not None else ""

    @property
    def events(self) -> list[str]:
        """What went wrong so far this episode (missed grasps, drops, misplacements)."""
        return [str(n) for n in self._ctx.events] if self._ctx is not None else []

    def on_step(self, step: int, action: np.ndarray) -> None:
        """Called by the runner's recorder after each executed step: the truth log's trace."""
        if self._ctx is not None and self._ctx.truth is not None:
            self._ctx.truth.watch(step, action)

    def truth_table(self):
        """This episode's attempts (`truth.TRUTH_SCHEMA`), or None before the first act."""
        return self._ctx.truth.table() if self._ctx is not None and self._ctx.truth is not None else None

    def params(self) -> dict:
        return {"kind": "scripted", **self.cfg.model_dump(mode="json")}

    def close(self) -> None:
        self._plan = None
