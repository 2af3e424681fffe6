"""The scripted expert as a `Policy`: privileged state in, (N, 7) action chunks out.

Per episode (`reset`) it seeds its noise from (seed, task id); on the first `act` it
plans from the live scene (`obs.sim`), so it copes with any start state. Each `act`
first credits the steps the runner actually executed of the previous chunk to the
primitive that produced them (the runner may execute fewer than returned), then asks the
plan for the next unfinished primitive and returns its actions (at most `chunk_len`;
fewer when a primitive ends, so the next decision sees live state).
"""

from __future__ import annotations

import numpy as np

from pipeline.config import ScriptedPolicyConfig
from pipeline.policies.base import Observation
from pipeline.policies.scripted.noise import Noise, episode_rng
from pipeline.policies.scripted.planner import plan_episode
from pipeline.policies.scripted.primitives import Primitive, emit
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.skills import Ctx, Plan
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
            noise = Noise(self.cfg.noise, episode_rng(self._seed, self._task_id or env.task.task_id))
            self._ctx = Ctx(scene=Scene(env), noise=noise, max_attempts=self.cfg.max_attempts)
            self._plan = plan_episode(self._ctx)
        if self._last is not None:
            prim, n, step0 = self._last
            prim.steps += max(0, min(obs.step - step0, n))
        eef, rot = env.eef_pose()
        while self._prim is None or self._prim.done(eef, rot):
            self._prim = next(self._plan)
        chunk = emit(self._prim, eef, rot, self.cfg.chunk_len, self._ctx.yaw_hold, self._ctx.approach_hold)
        chunk = self._ctx.noise.actions(chunk)
        self._last = (self._prim, len(chunk), obs.step)
        return chunk

    @property
    def phase(self) -> str:
        """Label of the primitive being executed (for debugging and tests)."""
        return self._prim.label if self._prim is not None else ""

    @property
    def events(self) -> list[str]:
        """What went wrong so far this episode (missed grasps, drops, misplacements)."""
        return list(self._ctx.events) if self._ctx is not None else []

    def params(self) -> dict:
        return {"kind": "scripted", **self.cfg.model_dump(mode="json")}

    def close(self) -> None:
        self._plan = None
