"""Seeded imperfection of the scripted expert.

Input: `ScriptedNoise` levels and a seed derived from (run seed, task id). Output: the
perturbations the skills ask for, drawn in the order they are needed, so an episode is
deterministic for a given (seed, task, init state): the simulator is deterministic and
so is the order of draws. All levels zero = the clean expert (and no draws change
anything).
"""

from __future__ import annotations

import zlib

import numpy as np

from pipeline.config import ScriptedNoise


def episode_rng(seed: int, task_id: str) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, zlib.crc32(task_id.encode())])


class Noise:
    def __init__(self, levels: ScriptedNoise, rng: np.random.Generator):
        self.levels = levels
        self.rng = rng
        # one speed factor per episode: a hasty or a careful operator
        s = levels.speed_scale
        self.speed = float(1.0 + rng.uniform(-s, s)) if s > 0 else 1.0

    def grasp_offset(self) -> np.ndarray:
        g = self.levels.grasp_offset_m
        xy = self.rng.normal(0.0, g, 2) if g > 0 else np.zeros(2)
        h = self.levels.approach_height_m
        z = self.rng.normal(0.0, h) if h > 0 else 0.0
        return np.array([xy[0], xy[1], z])

    def place_offset(self) -> np.ndarray:
        p = self.levels.place_offset_m
        xy = self.rng.normal(0.0, p, 2) if p > 0 else np.zeros(2)
        h = self.levels.approach_height_m
        z = abs(self.rng.normal(0.0, h)) if h > 0 else 0.0  # a release too high, never into the support
        return np.array([xy[0], xy[1], z])

    def timing(self) -> int:
        """Gripper timing error in steps: < 0 early, > 0 late."""
        t = self.levels.gripper_timing_steps
        return int(self.rng.integers(-t, t + 1)) if t > 0 else 0

    def actions(self, chunk: np.ndarray) -> np.ndarray:
        a = self.levels.action_noise
        if a <= 0:
            return chunk
        out = chunk.copy()
        out[:, :3] += self.rng.normal(0.0, a, (len(chunk), 3))
        out[:, 3:6] += self.rng.normal(0.0, a * 0.5, (len(chunk), 3))
        return np.clip(out, -1.0, 1.0)
