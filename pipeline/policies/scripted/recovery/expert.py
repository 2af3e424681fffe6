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
from pipeline.policies.scripted.primitives import Move, rotation_error
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
# an open hand's Move whose grip site went less than STALL_M and turned less than STALL_RAD
# over the last STALL_STEPS steps is pressed against something: it is over (its max_steps
# would end it where it stands, up to 80 steps later; the slowest moves, speed 0.3, go ~6 cm
# in 16 steps). A closed hand goes on: pressing a bottle down settles it into the rack's slot
# (measured: ended there, it was not in, and the next try took 125 steps more)
STALL_STEPS = 16
STALL_M = 0.005
STALL_RAD = 0.03


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
        self._poses: list[tuple[int, np.ndarray, np.ndarray]] = []  # (step, grip site, rotation) per chunk
        self._stall_prim: Move | None = None

    def reset(self, task: TaskSpec, seed: int) -> None:
        super().reset(task, seed)
        self.give_up_reason = None
        self.give_up_detail = ""
        self._now = 0
        self._eef = None
        self._unlocking = 0
        self._poses = []
        self._stall_prim = None

    def act(self, obs):
        self._now = obs.step
        self._end_stalled(obs)
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

    def _end_stalled(self, obs) -> None:
        """Mark the current Move done once it stalls (STALL_*) with the hand open, unless the
        elbow is locked: that is a pose the unlocking below gets out of, not something in the
        way. The window is counted in steps, not chunks: near a target a chunk is 1-2 steps."""
        prim = self._prim
        if not isinstance(prim, Move) or prim.label == "idle" or prim.gripper > 0:
            self._poses = []
            return
        if self._stall_prim is not prim:
            self._stall_prim, self._poses = prim, []
        pos, rot = obs.sim.eef_pose()
        self._poses.append((obs.step, pos, rot))
        back = [p for p in self._poses if obs.step - p[0] >= STALL_STEPS]
        if not back or self._unlocking:
            return
        _, p0, r0 = back[-1]
        if (float(np.linalg.norm(pos - p0)) < STALL_M and float(np.linalg.norm(rotation_error(r0, rot))) < STALL_RAD
                and not checks.elbow_locked(self._ctx.scene)):
            prim.steps = prim.max_steps
            self._poses = []

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
