"""The recovery expert as a configured policy (`policy.kind: recovery`), for `recover eval`.

`pipeline.policies.scripted.recovery.make_recovery_expert` builds the expert for a built
environment; a configured policy is made before any environment exists, so this wrapper
builds the expert on the first `act` of each episode from `obs.sim`, at zero variation
(the reference: what a competent recovering policy scores). Everything else is the
expert's own: its chunks, and `give_up_reason` when it stopped.
"""

from __future__ import annotations

import numpy as np

from pipeline.policies.base import Observation, Policy
from pipeline.sim import TaskSpec


class RecoveryExpertPolicy:
    cameras: tuple[str, ...] = ()
    image_size = 224

    def __init__(self, name: str | None = None):
        self.name = name or "recovery"
        self._task: TaskSpec | None = None
        self._seed = 0
        self._expert: Policy | None = None

    def reset(self, task: TaskSpec, seed: int) -> None:
        self._task, self._seed = task, int(seed)
        if self._expert is not None:
            self._expert.close()
        self._expert = None

    def act(self, obs: Observation) -> np.ndarray:
        if self._expert is None:
            if obs.sim is None:
                raise ValueError(f"policy {self.name}: the recovery expert needs privileged state (obs.sim)")
            from pipeline.policies.scripted.recovery import make_recovery_expert

            task = self._task or obs.sim.task
            self._expert = make_recovery_expert(obs.sim, task, seed=self._seed, variation=0.0)
            self._expert.reset(task, self._seed)
        return self._expert.act(obs)

    @property
    def give_up_reason(self):
        return getattr(self._expert, "give_up_reason", None)

    @property
    def phase(self) -> str:
        return getattr(self._expert, "phase", "")

    def params(self) -> dict:
        return {"kind": "recovery", "variation": 0.0}

    def close(self) -> None:
        if self._expert is not None:
            self._expert.close()
        self._expert = None
