"""Rotation conversions, through MuJoCo's own routines (the same conventions as its state).

Quaternions are (w, x, y, z), MuJoCo's order; robosuite's observations use (x, y, z, w).
"""

from __future__ import annotations

import numpy as np


def mat_to_quat(rot: np.ndarray) -> np.ndarray:
    """(w, x, y, z) of a 3x3 rotation matrix."""
    import mujoco

    q = np.empty(4)
    mujoco.mju_mat2Quat(q, np.asarray(rot, dtype=np.float64).reshape(-1))
    return q


def quat_to_mat(quat_wxyz: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a (w, x, y, z) quaternion."""
    import mujoco

    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, np.asarray(quat_wxyz, dtype=np.float64))
    return rot.reshape(3, 3)
