"""A tiny deterministic state-only policy for stage 1 tests (the scripted expert is
tested by its own suite): drifts the end effector along a seeded direction, closes the
gripper halfway. Module-level `make` is picklable, so spawned workers can build it."""

from __future__ import annotations

import numpy as np

from pipeline.policies.base import Observation


class DriftPolicy:
    cameras: tuple[str, ...] = ()
    image_size = 224

    def __init__(self, name: str = "drift", chunk: int = 8):
        self.name = name
        self.chunk = chunk
        self.calls = 0

    def reset(self, task, seed: int) -> None:
        rng = np.random.default_rng(seed)
        # float32-exact, so actions logged as float32 replay bit-identically
        self.direction = rng.uniform(-0.3, 0.3, size=3).astype(np.float32).astype(np.float64)
        self.seed = seed

    def act(self, obs: Observation) -> np.ndarray:
        self.calls += 1
        a = np.zeros((self.chunk, 7))
        a[:, :3] = self.direction
        a[:, 6] = 1.0 if obs.step >= 20 else -1.0
        return a

    def params(self) -> dict:
        return {"chunk": self.chunk}

    def close(self) -> None:
        pass


def make(cfg) -> DriftPolicy:
    return DriftPolicy(name=cfg.name or "drift")
