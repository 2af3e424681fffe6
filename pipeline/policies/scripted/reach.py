"""How far a grip-site point lies beyond the arm's easy reach.

With the hand pointing down, the Panda's elbow is straight when the grip site is about
0.85 m from the shoulder (measured: LIBERO kitchen scene 2, a bowl at the table's far
corner). A straight elbow is a singularity of the operational-space controller: it cannot
bend it again, so the arm stays stuck wherever it is carried next (transport never
arrives). Grasps past EASY_M lose to grasp points nearer the robot. Too near, the elbow
folds to its limit instead (joint 4 at -3.07 rad): a grip site less than NEAR_M from the
shoulder, low beside the base, is out of reach the other way (measured: LIVING_ROOM_SCENE4,
whose base stands closer to the objects than the kitchens': the hand stalled 0.383 m from
the shoulder, 4.5 cm short of a lying bottle's middle, until the time ran out).
"""

from __future__ import annotations

import numpy as np

SHOULDER_Z = 0.333  # Panda shoulder (joint 2) above the robot base
EASY_M = 0.80  # grip site this far from the shoulder still leaves the elbow bent
NEAR_M = 0.39  # ... and this near, still leaves it short of folding to its limit


def shoulder(env) -> np.ndarray:
    return env.robot_base() + [0.0, 0.0, SHOULDER_Z]


def overreach(env, point: np.ndarray) -> float:
    """Metres by which `point` lies beyond EASY_M from the shoulder (0 inside)."""
    return max(0.0, float(np.linalg.norm(np.asarray(point) - shoulder(env))) - EASY_M)


def underreach(env, point: np.ndarray) -> float:
    """Metres by which `point` lies within NEAR_M of the shoulder (0 outside)."""
    return max(0.0, NEAR_M - float(np.linalg.norm(np.asarray(point) - shoulder(env))))
