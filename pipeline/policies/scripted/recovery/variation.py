"""Seeded variation of the recovery expert, and the different-every-retry perturbation.

`variation` in [0, 1] scales small noise-model levels (approach point, approach height,
speed; never action noise or gripper timing): 0 is the exact zero-noise expert, used for
certificates and coverage; > 0 gives demonstrations that differ in approach and speed.
`RetryNoise` adds a fixed perturbation per retry of a subgoal to every grasp point, so a
retry reaches a little higher or to one side instead of repeating the failed motion.
"""

from __future__ import annotations

import numpy as np

from pipeline.config import ScriptedNoise
from pipeline.policies.scripted.noise import Noise

# grasp-point shift (x, y, z metres) on retry k of the same subgoal
RETRY_SHIFTS = np.array([[0, 0, 0], [0, 0, 0.008], [0.006, 0, -0.004], [-0.006, 0, 0.004], [0, 0.006, 0]])


def variation_levels(variation: float) -> ScriptedNoise:
    if not 0.0 <= variation <= 1.0:
        raise ValueError(f"recovery expert variation must lie in [0, 1], got {variation}")
    v = float(variation)
    return ScriptedNoise(grasp_offset_m=0.004 * v, approach_height_m=0.006 * v, speed_scale=0.25 * v,
                         place_offset_m=0.004 * v)


class RetryNoise(Noise):
    attempt: int = 0  # set by the planner before each subgoal attempt

    def grasp_offset(self) -> np.ndarray:
        return super().grasp_offset() + RETRY_SHIFTS[self.attempt % len(RETRY_SHIFTS)]
