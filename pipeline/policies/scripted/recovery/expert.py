"""The recovery expert as a `Policy`: the scripted expert's machinery (primitives, chunking,
truth log) with the recovery planner instead of the plain one, zero noise unless asked
for `variation`, and a `give_up_reason` when it stops short of the goal."""

from __future__ import annotations

import numpy as np

from pipeline.config import ScriptedPolicyConfig
from pipeline.policies.scripted.motion import Ctx, Plan
from pipeline.policies.scripted.noise import episode_rng
from pipeline.policies.scripted.notes import Halt, Note
from pipeline.policies.scripted.policy import ScriptedPolicy
from pipeline.policies.scripted.primitives import Move
from pipeline.policies.scripted.recovery import checks
from pipeline.policies.scripted.recovery.planner import recover
from pipeline.policies.scripted.recovery.reasons import GiveUp, GiveUpReason
from pipeline.policies.scripted.recovery.variation import RetryNoise, variation_levels
from pipeline.policies.scripted.scene import Scene
from pipeline.policies.scripted.truth import TruthLog
from pipeline.sim import TaskSpec

STUCK_M = 0.004  # grip-site travel over one chunk below which a Move counts as stuck
UNLOCK_STEPS = 4  # steps per unlocking chunk (re-checked after each)
UNLOCK_MAX = 24  # most steps of one unlocking
UNLOCK_TILT = 0.5  # rotation action (x 0.5 rad) about the horizontal axis that tilts the hand


class RecoveryExpert(ScriptedPolicy):
    def __init__(self, variation: float = 0.0, budget_steps: int | None = None, name: str | None = None):
        super().__init__(ScriptedPolicyConfig(noise=variation_levels(variation), max_attempts=1),
                         name or "recovery-expert")
        self.variation = float(variation)
        self.budget_steps = budget_steps
        self.give_up_reason: GiveUpReason | None = None
        self.give_up_detail = ""
        self._now = 0
        self._eef = None
        self._unlocking = 0

    def reset(self, task: TaskSpec, seed: int) -> None:
        super().reset(task, seed)
        self.give_up_reason = None
        self.give_up_detail = ""
        self._now = 0
        self._eef = None
        self._unlocking = 0

    def act(self, obs):
        self._now = obs.step
        prev = self._prim
        chunk = super().act(obs)
        eef = obs.sim.eef_pose()[0]
        # a Move that made no progress over its last chunk with the elbow locked: unlock it
        stuck = (isinstance(self._prim, Move) and self._prim is prev and self._eef is not None
                 and float(np.linalg.norm(eef - self._eef)) < STUCK_M and checks.elbow_locked(self._ctx.scene))
        self._eef = eef
        # once unlocking, go on until the elbow is well bent (or UNLOCK_MAX steps): a short
        # tilt is undone by the next chunks' turning the hand back, and the elbow locks again
        if stuck or (0 < self._unlocking < UNLOCK_MAX and isinstance(self._prim, Move)
                     and checks.elbow_straight(self._ctx.scene)):
            self._unlocking += UNLOCK_STEPS
            return self._unlock(chunk)
        self._unlocking = 0
        return chunk

    def _unlock(self, chunk: np.ndarray) -> np.ndarray:
        """A few steps that tilt the hand toward the robot base while still moving toward the
        primitive's target. A straight elbow at its limit is a singular pose: the controller
        then cannot pull the hand in (measured: 80 steps stuck, in every kind of skill); the
        tilt bends the elbow again within ~5 steps, and the next chunks turn the hand back."""
        d = checks.toward_base(self._ctx.scene, 1.0)
        axis = np.cross([0.0, 0.0, 1.0], -d)
        out = chunk[:UNLOCK_STEPS].copy()
        out[:, 3:6] = axis * UNLOCK_TILT
        prim, _, step0 = self._last
        self._last = (prim, len(out), step0)
        return out

    def _start(self, env) -> tuple[Ctx, Plan]:
        noise = RetryNoise(self.cfg.noise, episode_rng(self._seed, self._task_id or env.task.task_id))
        scene = Scene(env)
        ctx = Ctx(scene=scene, noise=noise, max_attempts=1, truth=TruthLog(scene, 0.0, noise.speed),
                  fist_wrist_free=True)
        return ctx, self._run(ctx)

    def _run(self, ctx: Ctx) -> Plan:
        try:
            yield from recover(ctx, lambda: self._now, self.budget_steps)
        except GiveUp as e:
            self.give_up_reason, self.give_up_detail = e.reason, e.detail
            ctx.events.append(Note(Halt.GIVE_UP, e.reason))
        s = ctx.scene
        while True:  # done or given up: hold still
            yield Move(target=s.eef(), gripper=-1.0 if checks.held(s) is None else 1.0, tol=-1.0,
                       max_steps=10**9, yaw=ctx.yaw_hold, label="idle")

    def reason_after(self, success: bool) -> GiveUpReason | None:
        """The reason for an episode's outcome: None on success; the expert's own reason, or
        `timeout` when the runner's horizon ended it first."""
        if success:
            return None
        return self.give_up_reason or GiveUpReason.TIMEOUT

    def params(self) -> dict:
        return {"kind": "recovery", "variation": self.variation, "budget_steps": self.budget_steps,
                **self.cfg.model_dump(mode="json")}
