"""How far a grip-site point lies beyond the arm's easy reach.

With the hand pointing down, the Panda's elbow is straight when the grip site is about
0.85 m from the shoulder (measured: LIBERO kitchen scene 2, a bowl at the table's far
corner). A straight elbow is a singularity of the operational-space controller: it cannot
bend it again, so the arm stays stuck wherever it is carried next (transport never
arrives). Grasps past EASY_M lose to grasp points nearer the robot.
"""

from __future__ import annotations

import numpy as np

SHOULDER_Z = 0.333  # Panda shoulder (joint 2) above the robot base
EASY_M = 0.80  # grip site this far from the shoulder still leaves the elbow bent


def shoulder(env) -> np.ndarray:
    return env.robot_base() + [0.0, 0.0, SHOULDER_Z]


def overreach(env, point: np.ndarray) -> float:
    """Metres by which `point` lies beyond EASY_M from the shoulder (0 inside)."""
    return max(0.0, float(np.linalg.norm(np.asarray(point) - shoulder(env))) - EASY_M)
